"""Executors (calib.executors): one map() interface; the FMU adapter's Jacobian is the same on
the serial executor, a local process pool and a Dask LocalCluster."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib.errors import InputError
from calib.executors import DaskExecutor, ProcessExecutor, SerialExecutor, get_executor


def test_map_keeps_task_order_and_reports_progress():
    tasks = [9.0, 1.0, 16.0, 4.0, 25.0]
    seen = []
    with ProcessExecutor(2) as pool:
        for ex in (SerialExecutor(), pool):
            seen.clear()
            assert ex.map(math.sqrt, tasks, progress=lambda done, total: seen.append((done, total))) == \
                [3.0, 1.0, 4.0, 2.0, 5.0]
            assert seen[-1] == (5, 5) and [d for d, _ in seen] == [1, 2, 3, 4, 5]


def test_unknown_executor_names_the_valid_ones():
    with pytest.raises(InputError, match="valid: serial, process, dask") as err:
        get_executor("mpi", source="run.toml")
    assert err.value.field == "kind" and "run.toml" in str(err.value)
    with pytest.raises(InputError, match="applies to kind = \"dask\" only"):
        get_executor("process", workers=2, address="tcp://127.0.0.1:8786")
    with pytest.raises(InputError, match="workers"):
        ProcessExecutor(0)


@pytest.fixture(scope="module")
def small_model():
    """The counts below are written for central differences (two runs per parameter), stated here since
    the mappings' default became forward."""
    from calib.fmu.build import build_fmu, mapping_path
    from calib.fmu.model import FmuModel
    from calib.rotor.library import load_rotor
    from test_fmu_model import CHANNELS, FAST, GRID, QUIET, WINDOW, conditions

    rotor = load_rotor("nrel5mw")
    path = build_fmu("B", rotor, GRID)
    make = lambda executor: FmuModel(path, mapping_path("B"), CHANNELS, parameters=["pitch_offset_blade1"],  # noqa: E731
                                     corrections=False,
                                     switches=QUIET, settings=FAST, steady=WINDOW, executor=executor,
                                     jacobian=dict(warm_start=True, differences="central", relative_step=0.01))
    return make, conditions(rotor, tsr=(6.0, 8.0, 10.0), pitch=(0.0, 2.0))


def test_process_pool_and_dask_give_the_serial_jacobian(small_model):
    """Every task (one operating point: base run and warm-started perturbations) is deterministic
    and self-contained, so where it runs cannot change a bit of the result (tolerance 1e-12)."""
    make, cond = small_model
    serial = make(SerialExecutor())
    p = np.array([q.nominal for q in serial.parameters]) + 0.01
    ev0, G0 = serial.jacobian(p, cond)
    serial.close()
    assert np.all(ev0.status == 0) and np.all(np.isfinite(G0)) and np.abs(G0).max() > 0
    for executor in (ProcessExecutor(2), DaskExecutor(workers=2)):
        with executor:
            model = make(executor)
            ev, G = model.jacobian(p, cond)
            np.testing.assert_allclose(ev.values, ev0.values, rtol=1e-12, atol=0)
            np.testing.assert_allclose(G, G0, rtol=1e-12, atol=1e-12 * np.abs(G0).max())
            ev2 = model.evaluate(p, cond)           # workers kept their instances: same again
            np.testing.assert_array_equal(ev2.values, ev0.values)


def test_pool_workers_end_when_the_run_is_killed(tmp_path):
    """A run killed with SIGKILL never shuts its pool down: its workers must not outlive it
    (they used to wait for their next task for ever, with the FMU processes they started)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    (tmp_path / "pidtask.py").write_text(
        "import os, time\n\ndef pid(_):\n    time.sleep(0.2)\n    return os.getpid()\n")
    script = tmp_path / "run.py"
    script.write_text(
        "import sys, time\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "from pidtask import pid\n"
        "from calib.executors import ProcessExecutor\n"
        "if __name__ == '__main__':\n"
        "    ex = ProcessExecutor(workers=2)\n"
        "    print(' '.join(map(str, sorted(set(ex.map(pid, range(6)))))), flush=True)\n"
        "    time.sleep(600)\n")
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    workers = [int(w) for w in proc.stdout.readline().split()]
    assert workers and all(Path(f"/proc/{w}").exists() for w in workers)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()

    def alive():
        out = []
        for w in workers:
            try:
                state = Path(f"/proc/{w}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except FileNotFoundError:
                continue
            if state != "Z":
                out.append(w)
        return out

    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and alive():
        time.sleep(0.2)
    assert not alive(), f"pool workers {alive()} outlived the killed run"


def test_a_pool_worker_of_the_calib_command_does_not_import_the_calibration_stack(tmp_path):
    """A spawned pool worker runs the main module of its parent before its first task; for ``calib run`` that is
    the console script, which imports :mod:`calib.cli`. Only the worker's tasks may import the calibration stack
    (scipy.stats: about 1 CPU s per worker, issue 38)."""
    import subprocess
    import sys

    script = tmp_path / "calib_script.py"           # what pip writes as the `calib` console script, plus a task
    script.write_text(
        "import sys\n"
        "from calib.cli import main\n\n"
        "def loaded(_):\n"
        "    import sys\n"
        "    return sorted(m for m in ('scipy', 'scipy.stats', 'calib.calibration', 'matplotlib') if m in sys.modules)\n\n"
        "if __name__ == '__main__':\n"
        "    from calib.executors import ProcessExecutor\n"
        "    with ProcessExecutor(workers=1) as ex:\n"
        "        print(ex.map(loaded, [0])[0], 'calib.cli' in sys.modules, flush=True)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == ["[]", "True"], out.stdout


class CountingExecutor(SerialExecutor):
    """A serial executor that counts its calls and the tasks it ran."""

    def __init__(self):
        super().__init__()
        self.calls, self.tasks = 0, 0

    def map(self, fn, tasks, progress=None):
        tasks = list(tasks)
        self.calls += 1
        self.tasks += len(tasks)
        return super().map(fn, tasks, progress)


def test_simulation_counts_are_the_executor_calls_made(small_model):
    """The model's tally (issue 38) counts what the executor ran: one call per model call, one task per
    point, 1 run per point of an evaluation and 1 + 2 n_params per point of a Jacobian, the model time
    of their windows, and a parallel efficiency in (0, 1]; the report line says the same."""
    from calib.fmu.faults import fault_sentences

    make, cond = small_model
    counting = CountingExecutor()
    model = make(counting)
    p = np.array([q.nominal for q in model.parameters])
    assert model.simulation_summary()["simulations"] == 0 and model.simulation_summary()["parallel_efficiency"] is None
    model.evaluate(p, cond)
    model.jacobian(p, cond)
    model.evaluate(p + 0.1, cond)
    s = model.simulation_summary()
    n, n_params = len(cond), len(model.parameters)
    assert (s["calls"], s["tasks"]) == (counting.calls, counting.tasks) == (3, 3 * n)
    assert s["simulations"] == 2 * n + n * (1 + 2 * n_params)
    steady = model.steady
    base = sum(sum(steady.window(rpm)[1:]) * steady.window(rpm)[0] for rpm in cond.rotor_speed)
    warm = sum(sum(steady.perturbation_window(rpm)[1:]) * steady.window(rpm)[0] for rpm in cond.rotor_speed)
    np.testing.assert_allclose(s["simulated_s"], 3 * base + 2 * n_params * warm, rtol=1e-9)
    assert 0 < s["busy_worker_s"] <= s["wall_s"] and 0 < s["parallel_efficiency"] <= 1
    line = fault_sentences(model.fault_summary())["FMU simulations and their wall time"]
    assert line.startswith(f"{s['simulations']} simulations ({3 * n} points in 3 calls)")
    model.close()
    with ProcessExecutor(2) as pool:
        model = make(pool)
        model.jacobian(p, cond)
        s = model.simulation_summary()
        assert s["workers"] == 2 and s["simulations"] == n * (1 + 2 * n_params)
        assert 0 < s["parallel_efficiency"] <= 1
        model.close()


def test_a_base_run_simulated_before_is_reused_bit_for_bit(small_model):
    """Issue 38: an evaluation at parameters already simulated (by any model of the same plan: the unit
    check's at the nominal vector, a Gauss-Newton trial) simulates nothing, and a cold Jacobian there reuses
    the base runs; values and sensitivities are those of fresh simulations, bit for bit."""
    from calib.fmu.base_runs import BaseRunCache

    make_warm, cond = small_model
    n = len(cond)
    fresh = _cold(make_warm)
    p = np.array([q.nominal for q in fresh.parameters]) + 0.02
    ev0, G0 = fresh.jacobian(p, cond)
    shared = BaseRunCache()
    check, model = _cold(make_warm, shared), _cold(make_warm, shared)   # e.g. the unit check's model and a stage's
    ev1 = check.evaluate(p, cond)
    ev2 = model.evaluate(p, cond)
    ev3, G3 = model.jacobian(p, cond)
    assert check.simulation_summary()["simulations"] == n
    s = model.simulation_summary()
    assert s["simulations"] == n * 2 * len(model.parameters) and s["reused_base_runs"] == 2 * n
    for ev in (ev1, ev2, ev3):
        np.testing.assert_array_equal(ev.values, ev0.values)
    np.testing.assert_array_equal(G3, G0)
    for m in (fresh, check, model):
        m.close()


def test_cold_perturbed_runs_are_reused_across_calls_and_models(small_model):
    """Issue 38 (c): a cold perturbed run is a cold run at the perturbed values. A Jacobian taken again at the
    same point and parameters simulates nothing; a model calibrating one more parameter (a diagnosis
    candidate on top of the base model), at the base model's point with the new parameter at its start
    value, simulates only the new parameter's runs. Every value and column is that of fresh simulations
    (a model with its own cache), bit for bit."""
    from calib.fmu.base_runs import BaseRunCache

    make_warm, cond = small_model
    n = len(cond)
    shared = BaseRunCache()
    base = _cold(make_warm, shared)
    p = np.array([q.nominal for q in base.parameters]) + 0.02
    ev0, G0 = base.jacobian(p, cond)
    ev1, G1 = base.jacobian(p, cond)
    s = base.simulation_summary()
    assert s["simulations"] == n * 3 and s["calls"] == 1          # the second call sent nothing
    assert s["reused_base_runs"] == n and s["reused_perturbed_runs"] == 2 * n
    np.testing.assert_array_equal(G1, G0)
    np.testing.assert_array_equal(ev1.values, ev0.values)
    bigger = _cold(make_warm, shared, ["pitch_offset_blade1", "pitch_offset_blade2"])
    fresh = _cold(make_warm, None, ["pitch_offset_blade1", "pitch_offset_blade2"])
    assert bigger.parameters[1].nominal == 0.0
    q = np.array([p[0], 0.0])
    ev2, G2 = bigger.jacobian(q, cond)
    ev3, G3 = fresh.jacobian(q, cond)
    s2 = bigger.simulation_summary()
    assert s2["simulations"] == 2 * n, s2                               # only the new parameter's two runs
    assert s2["reused_base_runs"] == n and s2["reused_perturbed_runs"] == 2 * n
    assert fresh.simulation_summary()["simulations"] == 5 * n
    np.testing.assert_array_equal(G2, G3)
    np.testing.assert_array_equal(G2[:, :, 0], G0[:, :, 0])
    np.testing.assert_array_equal(ev2.values, ev3.values)
    assert np.all(np.isfinite(G3)) and np.abs(G3[:, :, 1]).max() > 0
    for m in (base, bigger, fresh):
        m.close()


def test_canonical_parameter_key_ignores_values_at_the_start_value(small_model):
    """The reuse key of a parameter vector names only the values off the FMU's start values: a model with an
    extra parameter at its start value has the key of one without it; any other value, -0.0 included, differs."""
    make_warm, _ = small_model
    one = _cold(make_warm, None)
    two = _cold(make_warm, None, ["pitch_offset_blade1", "pitch_offset_blade2"])
    key = lambda m, p: m._params.canonical(m._params.assignments(np.asarray(p, float)))  # noqa: E731
    assert key(one, [0.3]) == key(two, [0.3, 0.0]) != key(two, [0.3, 0.1])
    assert key(two, [0.3, -0.0]) != key(one, [0.3])
    assert key(one, [0.0]) == () and len(key(two, [0.3, 0.1])) == 2


def _cold(make, base_runs=None, parameters=None):
    """The small model with warm start off (perturbed runs from scratch)."""
    from calib.fmu.model import FmuModel

    m = make(SerialExecutor())
    return FmuModel(m.fmu_path, m.mapping, [c.name for c in m.channels],
                    parameters=parameters or [q.name for q in m.parameters],
                    corrections=False, switches=m._options["switches"], settings=m._options["settings"],
                    steady=m._options["steady"], executor=SerialExecutor(),
                    jacobian=dict(warm_start=False, differences="central", relative_step=0.01),
                    base_runs=base_runs)


def test_process_totals_add_every_model_call_and_reset():
    """The process-wide tally (what a diagnosis benchmark reads) is the sum of the models' own tallies."""
    from calib.fmu.plan import PointResult, RunOutcome
    from calib.fmu.tally import SimulationTally, process_totals

    def result(n_runs, busy):
        run = RunOutcome(0, "", np.zeros(1), np.zeros((2, 1)), np.zeros((1, 3), complex), simulated=2.0)
        return PointResult(0, run, [run] * (n_runs - 1), busy=busy)

    process_totals(reset=True)
    a, b = SimulationTally(), SimulationTally()
    a.record([result(3, 0.5), result(1, 0.25)], 1.0, 2)
    b.record([result(5, 1.0)], 2.0, 2)
    b.add_reused(4, 7)
    t = process_totals()
    assert (t["calls"], t["tasks"], t["simulations"]) == (2, 3, 9) == (a.calls + b.calls, a.tasks + b.tasks,
                                                                         a.simulations + b.simulations)
    assert t["simulated_s"] == pytest.approx(18.0) and t["busy_worker_s"] == pytest.approx(1.75)
    assert t["parallel_efficiency"] == pytest.approx(1.75 / (3.0 * 2))
    assert (t["reused_base_runs"], t["reused_perturbed_runs"]) == (4, 7) == (b.reused, b.reused_perturbed)
    assert process_totals(reset=True)["simulations"] == 9 and process_totals()["simulations"] == 0
