"""Figures drawn in forked workers: the same files as in one process, errors and Ctrl-C handled."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from test_report_atomic import broken_files
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.measurements import synthesize
from calib.report import figures as F
from calib.report.atomic import is_temporary
from calib.report.parallel import fork_available, partition
from calib.types import nominal_vector

ROOT = Path(__file__).resolve().parents[1]
@pytest.fixture(scope="module")
def fresh_outcomes():
    """Outcomes of the fork tests run in a fresh interpreter, or None when this one can fork.

    An earlier test of the session (a Dask executor: its ``Dask-Offload`` thread lives as long
    as the process) may leave threads running, and then this process draws figures in one
    process by design. The fork tests then run once more in a fresh ``python -m pytest`` of
    this module, and each asserts its own outcome there, so they run in every suite order.
    """
    if fork_available():
        return None
    if os.environ.get("CALIB_FRESH_FORK_TESTS"):
        pytest.fail("threads are running even in a fresh interpreter: the fork tests cannot run")
    env = dict(os.environ, CALIB_FRESH_FORK_TESTS="1")
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", "-m",
                           "not statistics",
                           __file__, "-k", " or ".join(FORK_TESTS)], capture_output=True, text=True, cwd=ROOT,
                          env=env, timeout=600)
    outcomes = {}
    for line in done.stdout.splitlines():
        word, _, rest = line.partition(" ")
        if word in ("PASSED", "FAILED", "ERROR", "SKIPPED") and "::" in rest:
            outcomes[rest.split("::", 1)[1].split()[0]] = (word, done.stdout[-3000:])
    return outcomes


@pytest.fixture
def forks_here(request, fresh_outcomes) -> bool:
    """True when the test runs here; False after asserting that it passed in a fresh interpreter
    (the test then returns at once: its body forks, which this process does not)."""
    if fresh_outcomes is None:
        return True
    word, log = fresh_outcomes.get(request.node.name, ("NOT RUN", ""))
    assert word == "PASSED", f"{request.node.name} in a fresh interpreter: {word}\n{log}"
    return False


FORK_TESTS = ("test_workers_write_the_same_files_as_one_process",
              "test_a_figure_failing_in_a_worker_raises_its_own_error",
              "test_sigint_stops_the_workers_and_leaves_no_truncated_file")


@pytest.fixture(scope="module")
def result():
    model = TwinModel(channels=("power", "thrust", "root_flap_moment"))
    p_true = nominal_vector(model.parameters)
    p_true[:model.grid.n_lift] = 0.05 * np.sin(np.arange(model.grid.n_lift))
    meas = synthesize(model, p_true, twin_conditions(),
                      relative_sigma={"power": 0.005, "thrust": 0.005, "root_flap_moment": 0.005}, seed=5)
    return Calibrator(model, meas, CalibrationSettings(sigma_bar=0.3), name="twin").run()


def test_partition_balances_the_costs_and_keeps_the_order():
    costs = {"a": 1.0, "b": 5.0, "c": 1.0, "d": 2.0, "e": 2.0, "f": 1.0}
    groups = partition(costs, 2)
    assert sorted(n for g in groups for n in g) == sorted(costs)
    loads = [sum(costs[n] for n in g) for g in groups]
    assert max(loads) == 6.0                                  # the best split of 12 is 6 + 6
    for g in groups:
        assert g == sorted(g, key=list(costs).index)
    assert sorted(partition(costs, 10)) == [[n] for n in sorted(costs)]     # at most one group per task
    assert partition(costs, 1) == [list(costs)]


def test_workers_write_the_same_files_as_one_process(result, tmp_path, forks_here):
    if not forks_here:
        return
    def truth(alpha_deg, eta):
        return 0.05 * np.cos(np.radians(alpha_deg)) + 0 * eta, 0.001 + 0 * alpha_deg

    serial = F.write_figures(result, tmp_path / "one", truth=truth, workers=1)
    messages = []
    forked = F.write_figures(result, tmp_path / "two", truth=truth, workers=2, progress=messages.append)
    assert list(forked) == list(serial)
    for name in serial:
        assert forked[name]["png"].parent == tmp_path / "two"
        assert forked[name]["png"].read_bytes() == serial[name]["png"].read_bytes(), name
    assert "2 processes" in messages[0]
    assert sorted(m.split()[3] for m in messages[1:-1]) == sorted(serial)   # one line per figure
    plain = F.write_figures(result, tmp_path / "plain", workers=2)
    assert plain["polars"]["png"].read_bytes() != forked["polars"]["png"].read_bytes()   # the truth is drawn
    assert not [p for p in (tmp_path / "two").iterdir() if is_temporary(p)]


def test_a_figure_failing_in_a_worker_raises_its_own_error(result, tmp_path, monkeypatch, forks_here):
    if not forks_here:
        return
    def broken(res, truth=None):
        raise ValueError("this figure cannot be drawn")

    monkeypatch.setitem(F.FIGURES, "broken", broken)
    with pytest.raises(ValueError, match="cannot be drawn"):
        F.write_figures(result, tmp_path, workers=2)


CHILD = textwrap.dedent('''
    import signal
    import sys
    from pathlib import Path

    signal.signal(signal.SIGINT, signal.default_int_handler)   # even if started with SIGINT ignored
    from calib.report import figures as F
    from calib.calibration.result_files import load_result

    res = load_result(sys.argv[1])
    print("ready", flush=True)
    try:
        F.write_figures(res, Path(sys.argv[2]), formats=("svg", "png"), workers=2,
                        progress=lambda text: print(text, flush=True))
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(130)
''')


def _interrupt(tmp_path, saved: Path, whole_group: bool):
    script = tmp_path / "writer.py"
    script.write_text(CHILD)
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen([sys.executable, str(script), str(saved), str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    try:
        lines = []
        for line in proc.stdout:                          # the first figure is done: the rest are drawing
            lines.append(line.strip())
            if " figure 1/" in line:
                break
        assert lines and " figure 1/" in lines[-1], (lines, proc.stderr.read())
        time.sleep(0.2)
        if whole_group:
            os.killpg(proc.pid, signal.SIGINT)            # what Ctrl-C in a terminal does
        else:
            proc.send_signal(signal.SIGINT)               # the parent alone
        rest, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130 and rest.strip().endswith("interrupted"), (rest, err)
    assert "Traceback" not in err, err                     # no worker printed a traceback
    time.sleep(0.5)
    with pytest.raises(ProcessLookupError):                # no worker left running
        os.killpg(proc.pid, 0)
    return out


@pytest.mark.parametrize("whole_group", [True, False], ids=["ctrl-c", "sigint-to-parent"])
def test_sigint_stops_the_workers_and_leaves_no_truncated_file(result, tmp_path, whole_group, forks_here):
    if not forks_here:
        return
    saved = tmp_path / "saved"
    result.save(saved)
    out = _interrupt(tmp_path, saved, whole_group)
    assert broken_files(out) == []
    written = {p.stem for p in out.iterdir()}
    applicable = len(F.FIGURES) - (not result.identifiability.truncation)  # the truncation curve needs sigma_bar = "auto"
    assert 1 <= len(written) < applicable                  # stopped part-way, not finished


FINALIZER_CHILD = textwrap.dedent('''
    import os
    import signal
    import time
    from calib.report.parallel import run_forked

    parent = os.getpid()

    class Finalized:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGTERM)

    def render(name):
        if os.getpid() != parent:
            obj = Finalized()
            del obj
            time.sleep(0.5)                   # the worker is stopping: this figure is never reported
        return name.upper()

    print(run_forked({"a": 1.0, "b": 1.0}, render, 2), flush=True)
''')


def test_a_stop_signal_landing_in_a_finalizer_prints_no_traceback(tmp_path):
    """Ctrl-C reaches a worker and the parent's SIGTERM follows at once; when the first lands in a
    finalizer (where Python can only report it through the unraisable hook) and the second
    arrives while it unwinds, the worker still stops without a traceback and the parent draws
    its figures. A plain interpreter (pytest's own unraisable hook would hide the traceback)."""
    script = tmp_path / "finalizer.py"
    script.write_text(FINALIZER_CHILD)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "{'a': 'A', 'b': 'B'}", (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr
