"""A faulty vendor FMU costs seconds, not a timeout per call: points that crashed, hung or got a
fatal status are quarantined (not simulated again, retried once when the parameters move far),
error statuses are not, the timeout adapts to the cost of healthy runs, and no other point is
touched.

The FMU is ``tests/data/fmu/FaultyRotor.py`` (PythonFMU, built here): it crashes, hangs, refuses
a step and raises at chosen wind speeds, and writes a line to ``$FAULTY_ROTOR_LOG`` before every
fault, so the simulations of the faulty points are counted outside calib.
"""

from __future__ import annotations

import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from pythonfmu_export import export_fmu

from calib.fmu import plan as fp
from calib.fmu import worker as fw
from calib.fmu.channels import channel_values
from calib.fmu.faults import FaultLedger
from calib.fmu.model import FmuModel
from calib.types import OperatingConditions, Status

DATA = Path(__file__).parent / "data" / "fmu"
MAPPING = DATA / "faulty_rotor_mapping.toml"
WIND = np.arange(5.0, 11.0, 0.5)                       # 12 points [m/s]
FAULTS = {"crash": 6.0, "hang": 7.5, "error": 9.0, "fatal": 10.0}
SETTINGS = {f"{kind}_wind_speed": v for kind, v in FAULTS.items()}


@pytest.fixture(scope="module")
def faulty_fmu(tmp_path_factory):
    out = tmp_path_factory.mktemp("faulty_fmu")
    return export_fmu("FaultyRotor", out)


def conditions(wind=WIND) -> OperatingConditions:
    """A power curve: rotor speed 7-16 rpm up to 11 m/s, pitch 3 deg per m/s above it."""
    wind = np.asarray(wind, float)
    rpm = np.clip(7.0 + 9.0 * (wind - 5.0) / 6.0, 7.0, 16.0)
    return OperatingConditions(wind, rpm, np.clip(3.0 * (wind - 11.0), 0.0, None))


def model(path, faults: bool = True, settings: dict | None = None, **kw) -> FmuModel:
    """The test rotor; ``faults``: all four faults on (``settings``: chosen ones)."""
    settings = settings if settings is not None else SETTINGS if faults else {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")          # PythonFMU's empty InitialUnknowns (see test_fmu_generic)
        return FmuModel(path, MAPPING, ["power", "thrust"], settings=settings, **kw)


def fault_log(path: Path) -> Counter:
    """Simulations that met each fault, as the FMU logged them."""
    if not path.is_file():
        return Counter()
    return Counter(line.split()[0] for line in path.read_text().splitlines())


def scaled(m: FmuModel, steps) -> np.ndarray:
    """Nominal parameters moved by ``steps`` parameter scales."""
    return np.array([q.nominal + s * q.scale for q, s in zip(m.parameters, steps)])


# calls of the quarantine scenario: (kind, parameter steps in scales); the 4th moves cp_gain by
# 2 scales from where the points failed (one retry), the 5th by 2 the other way (no second retry)
CALLS = [("evaluate", [0, 0, 0, 0]), ("jacobian", [0, 0, 0, 0]), ("evaluate", [0.3, 0, 0, 0.3]),
         ("jacobian", [2, 0, 0, 0]), ("evaluate", [-2, 0, 0, 0]), ("jacobian", [0, 0, 0, 0])]


def run_calls(m: FmuModel, cond) -> list:
    out = []
    for kind, steps in CALLS:
        p = scaled(m, steps)
        out.append(m.jacobian(p, cond) if kind == "jacobian" else (m.evaluate(p, cond), None))
    return out


# ------------------------------------------------------------------ (a) quarantine on the FMU
def test_crashing_hanging_and_fatal_points_are_simulated_at_most_twice(faulty_fmu, tmp_path, monkeypatch):
    """Six evaluations and Jacobians with a 3 s timeout: the crashing, hanging and fatal points
    are simulated once, then once more when cp_gain has moved 2 scales, and never again; the
    erroring point is simulated at every call (not quarantined); every other point equals the
    fault-free run, values and sensitivities."""
    monkeypatch.setenv("FAULTY_ROTOR_LOG", str(tmp_path / "faults.log"))
    cond = conditions()
    clean, faulty = model(faulty_fmu, faults=False), model(faulty_fmu, timeout=3.0)
    try:
        ref = run_calls(clean, cond)
        t0 = time.perf_counter()
        got = run_calls(faulty, cond)
        wall = time.perf_counter() - t0
    finally:
        clean.close()
        faulty.close()
    seen = fault_log(tmp_path / "faults.log")
    assert seen == {"crash": 2, "hang": 2, "fatal": 2, "error": len(CALLS)}, seen
    summary = faulty.fault_summary()
    assert wall < 2 * 3.0 + 10.0, wall          # two waits of the 3 s timeout (six without quarantine: 18 s)
    bad = np.isin(cond.wind_speed, list(FAULTS.values()))
    for (ev_ref, g_ref), (ev, g) in zip(ref, got):
        assert np.all(ev.status[~bad] == Status.CONVERGED) and np.all(ev.status[bad] != Status.CONVERGED)
        np.testing.assert_allclose(ev.values[~bad], ev_ref.values[~bad], rtol=1e-12)
        assert np.all(np.isnan(ev.values[bad]))
        if g is not None:
            np.testing.assert_allclose(g[~bad], g_ref[~bad], rtol=1e-9, atol=1e-9 * np.abs(g_ref).max())
    hang = cond.wind_speed == FAULTS["hang"]
    last = got[-1][0]
    assert last.status[hang][0] == Status.TIMEOUT and "quarantined" in last.messages[np.flatnonzero(hang)[0]]
    by_fault = {e["fault"]: e for e in summary["quarantine"]}
    assert set(by_fault) == {"crash", "timeout", "fatal"}
    for e in by_fault.values():
        assert e["retried"] and e["retry_call"] == 4 and e["retry_outcome"] == "failed again" and e["active"]
        assert e["faults"] == 2 and e["skipped"] == len(CALLS) - 2
    assert by_fault["timeout"]["conditions"]["wind_speed"] == FAULTS["hang"]
    errors = {e["fault"]: e for e in summary["errors"]}
    assert errors["error"]["count"] == len(CALLS) and errors["fatal"]["count"] == 2
    assert errors["error"]["conditions"]["wind_speed"] == FAULTS["error"]


@pytest.mark.slow
def test_after_a_fatal_status_the_process_is_replaced_and_later_points_are_unharmed(faulty_fmu):
    """FMI allows no call after fmi2Fatal; reusing the library anyway (a new instance in the
    same process) made PythonFMU crash with SIGSEGV at a healthy point some runs later (in most
    of the rounds below). The worker process is replaced instead: six rounds of a Jacobian's
    tasks with the fatal point first give every other point the fault-free values."""
    wind = np.round(np.linspace(5.0, 12.05, 48), 2)
    cond = conditions(wind)
    clean = model(faulty_fmu, faults=False)
    faulty = model(faulty_fmu, settings={"fatal_wind_speed": float(wind[5])})
    p = scaled(clean, [0, 0, 0, 0])
    _, tasks, _ = faulty._tasks(p, cond, perturb=True)
    order = tasks[5:] + tasks[:5]
    worker = fw.WorkerProcess(faulty._plan, 60.0)
    try:
        ref = clean.evaluate(p, cond).values
        results = [worker.run_point(t) for _ in range(6) for t in order]
    finally:
        worker.close()
        clean.close()
        faulty.close()
    healthy = [r for r in results if r.index != 5]
    broken = [getattr(o, "message", "not run") for r in healthy for o in (r.base, *r.perturbations)
              if o is None or not o.ok]
    assert not broken, broken[:3]
    values = channel_values([r.base for r in healthy], faulty._channel_specs, faulty._keys_for_values)
    np.testing.assert_allclose(values, ref[[r.index for r in healthy]], rtol=1e-12)
    hit = [r for r in results if r.index == 5]
    assert all(r.base.fault == "fatal" and "fatal status" in r.base.message and r.restarts == 1 for r in hit)
    assert worker.restarts == 6


# ------------------------------------------------------------------ (b) adaptive timeout
@pytest.mark.parametrize("walls,configured,multiple,floor,expected", [
    ([], 60.0, 10.0, 5.0, 60.0),                     # nothing measured: the configured timeout
    ([0.001, 0.002, 0.003], 60.0, 10.0, 5.0, 5.0),   # fast FMU: the floor
    ([1.0, 2.0, 3.0], 60.0, 10.0, 5.0, 20.0),        # 10 x the median
    ([1.0, 2.0, 300.0], 60.0, 10.0, 5.0, 20.0),      # a slow outlier does not move the median
    ([10.0, 12.0], 60.0, 10.0, 5.0, 60.0),           # never above the configured timeout
    ([0.01], 3.0, 10.0, 5.0, 3.0),                   # ... even when that is below the floor
    ([0.5, 0.7], 60.0, 4.0, 1.0, 2.4),               # another multiple and floor
])
def test_adaptive_timeout_rule(walls, configured, multiple, floor, expected):
    assert fp.adaptive_timeout(walls, configured, multiple, floor) == pytest.approx(expected, rel=1e-12)


def test_timeout_policy_defaults_and_worker_measurements():
    assert (fp.TIMEOUT_MULTIPLE, fp.TIMEOUT_FLOOR) == (10.0, 5.0)
    policy = fp.TimeoutPolicy(60.0, walls=(1.0, 1.0))
    assert policy.timeout() == pytest.approx(10.0)
    assert policy.timeout([3.0, 3.0, 3.0]) == pytest.approx(30.0)     # the worker's own runs count too
    assert fp.TimeoutPolicy(60.0).timeout() == 60.0


@pytest.mark.slow
def test_worker_adapts_its_timeout_after_one_healthy_run(faulty_fmu):
    """A worker given the default 60 s policy stops a hang after the 5 s floor once it has
    measured one healthy run (within one batch: the planner knows nothing yet)."""
    m = model(faulty_fmu)
    cond = conditions([5.0, FAULTS["hang"]])
    _, tasks, _ = m._tasks(scaled(m, [0, 0, 0, 0]), cond, perturb=False)
    worker = fw.WorkerProcess(m._plan, fp.TimeoutPolicy(60.0))
    try:
        assert worker.timeout == 60.0
        healthy = worker.run_point(tasks[0])
        assert healthy.base.ok and worker.timeout == fp.TIMEOUT_FLOOR
        t0 = time.perf_counter()
        hung = worker.run_point(tasks[1])
        wall = time.perf_counter() - t0
    finally:
        worker.close()
        m.close()
    assert hung.base.status == Status.TIMEOUT and hung.base.fault == "timeout" and hung.restarts == 1
    assert "timeout of 5 s" in hung.base.message
    assert fp.TIMEOUT_FLOOR <= wall < fp.TIMEOUT_FLOOR + 10.0, wall


def test_model_records_the_timeout_in_force(faulty_fmu):
    m = model(faulty_fmu, faults=False)
    try:
        assert m.fault_summary()["timeout"]["in_force_s"] == 60.0
        m.evaluate(scaled(m, [0, 0, 0, 0]), conditions())
        t = m.fault_summary()["timeout"]
    finally:
        m.close()
    assert t["healthy_runs"] == WIND.size and t["median_healthy_s"] > 0
    assert t["in_force_s"] == pytest.approx(fp.adaptive_timeout([t["median_healthy_s"]], 60.0))
    assert t["changes"] and t["changes"][0]["timeout_s"] == t["in_force_s"]


# ------------------------------------------------------------------ (c) keyed by operating point
def _task(k, wind, rpm, pitch):
    return fp.PointTask(k, (fp.Assignment("real", (0, 1, 2), (wind, rpm, pitch)),), (), (), rpm)


def _result(task, fault=""):
    if not fault:
        return fp.PointResult(task.index, fp.RunOutcome.failed(2, Status.CONVERGED, "", 0.01), [])
    status = Status.TIMEOUT if fault == "timeout" else Status.SIMULATION_FAILED
    return fp.PointResult(task.index, fp.RunOutcome.failed(2, status, f"a {fault}", 0.01, fault), [])


def _ledger_call(ledger, points, p, faults=None):
    """One planned call; ``faults``: index -> fault kind of the simulated points. Returns
    (simulated indices, results)."""
    tasks = [_task(k, *pt) for k, pt in enumerate(points)]
    cond = OperatingConditions(*(np.array(c, float) for c in zip(*points)))
    run, results = ledger.plan(tasks, p, 2)
    for k in run:
        results[k] = _result(tasks[k], (faults or {}).get(k, ""))
    ledger.record(tasks, results, run, p, cond)
    return run, results


def test_quarantine_is_keyed_by_the_operating_point_and_retried_once_when_far():
    """A point that crashed is skipped later; points sharing its wind speed, rotor speed or
    pitch but not all of them are simulated; an error is never quarantined; the retry comes
    at one parameter scale (not 0.99), once."""
    ledger = FaultLedger(["a", "b"], [0.1, 2.0], 60.0)
    points = [(8.0, 12.0, 0.0), (8.0, 12.0, 1.0), (8.0, 13.0, 0.0), (9.0, 12.0, 0.0), (10.0, 14.0, 0.0)]
    p0 = np.array([1.0, 0.0])
    run, _ = _ledger_call(ledger, points, p0, {0: "crash", 4: "error"})
    assert run == [0, 1, 2, 3, 4]
    run, res = _ledger_call(ledger, points, p0 + [0.099, 1.98])            # 0.99 scale: not far
    assert run == [1, 2, 3, 4]
    assert res[0].base.status == Status.SIMULATION_FAILED and "quarantined" in res[0].base.message
    assert res[0].base.fault == "quarantined" and np.all(np.isnan(res[0].base.mean))
    run, _ = _ledger_call(ledger, points, p0 + [0.0, 2.0], {0: "timeout"})  # 1 scale of b: the retry
    assert run == [0, 1, 2, 3, 4]
    run, _ = _ledger_call(ledger, points, p0 + [1.0, 10.0])                # far again: no second retry
    assert run == [1, 2, 3, 4]
    s = ledger.summary()
    assert [e["conditions"]["wind_speed"] for e in s["quarantine"]] == [8.0]
    e = s["quarantine"][0]
    assert (e["conditions"]["pitch"], e["conditions"]["rotor_speed"]) == (0.0, 12.0)
    assert e["fault"] == "timeout" and e["status"] == Status.TIMEOUT and e["faults"] == 2 and e["skipped"] == 2
    assert e["retried"] and e["retry_outcome"] == "failed again" and e["active"]
    assert s["errors"][0]["conditions"]["wind_speed"] == 10.0 and s["errors"][0]["count"] == 1
    assert s["counts"]["points_skipped"] == 2 and s["counts"]["retries"] == 1


def test_a_retry_that_succeeds_releases_the_point():
    ledger = FaultLedger(["a"], [0.1], 60.0)
    points = [(8.0, 12.0, 0.0), (9.0, 12.0, 0.0)]
    _ledger_call(ledger, points, [1.0], {0: "crash"})
    run, _ = _ledger_call(ledger, points, [1.2])
    assert run == [0, 1]
    e = ledger.summary()["quarantine"][0]
    assert not e["active"] and e["retry_outcome"] == "recovered"
    run, _ = _ledger_call(ledger, points, [1.0])
    assert run == [0, 1]


@pytest.mark.slow
def test_quarantine_with_a_process_executor(faulty_fmu, tmp_path, monkeypatch):
    """The same decisions with two worker processes: each faulty point is simulated once in two
    calls, and every other point equals the serial fault-free run."""
    from calib.executors import ProcessExecutor

    monkeypatch.setenv("FAULTY_ROTOR_LOG", str(tmp_path / "faults.log"))
    cond = conditions()
    clean = model(faulty_fmu, faults=False)
    p = scaled(clean, [0, 0, 0, 0])
    with ProcessExecutor(workers=2) as ex:
        faulty = model(faulty_fmu, timeout=3.0, executor=ex)
        try:
            ref = clean.evaluate(p, cond)
            evs = [faulty.evaluate(p, cond) for _ in range(2)]
        finally:
            clean.close()
            faulty.close()
    seen = fault_log(tmp_path / "faults.log")
    assert seen == {"crash": 1, "hang": 1, "fatal": 1, "error": 2}, seen
    bad = np.isin(cond.wind_speed, list(FAULTS.values()))
    for ev in evs:
        np.testing.assert_allclose(ev.values[~bad], ref.values[~bad], rtol=1e-12)
        assert np.all(ev.status[bad] != Status.CONVERGED) and np.all(ev.status[~bad] == Status.CONVERGED)


# ------------------------------------------------------------------ the run's report
@pytest.mark.slow
def test_calib_run_reports_the_timeout_and_the_quarantined_points(faulty_fmu, tmp_path):
    """calib run on the faulty FMU (crash and hang on; 3 s timeout) finishes, and the stage's
    report lines state the timeout in force and each quarantined point with its status."""
    from calib.calibration.result_files import load_result
    from calib.cli import main
    from calib.measurements import synthesize

    clean = model(faulty_fmu, faults=False)
    truth = np.array([q.nominal for q in clean.parameters]) * [1.05, 0.97, 1.0, 1.0]
    synthesize(clean, truth, conditions(), relative_sigma={"power": 0.01, "thrust": 0.01},
               seed=3).write_csv(tmp_path / "field.csv")
    clean.close()
    (tmp_path / "faulty.toml").write_text(f"""name = "faulty FMU"
[model]
kind = "fmu"
fmu = "{faulty_fmu.as_posix()}"
mapping = "{MAPPING.as_posix()}"
parameters = ["cp_gain", "ct_gain"]
settings = {{ crash_wind_speed = {FAULTS['crash']}, hang_wind_speed = {FAULTS['hang']} }}
timeout = 3.0
[measurements]
file = "field.csv"
[calibration]
noise = "known"
[[stages]]
name = "loads"
channels = ["power", "thrust"]
retain = "all"
""")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["run", str(tmp_path / "faulty.toml"), "--out", str(tmp_path / "out"), "-q"]) == 0
    checks = load_result(tmp_path / "out" / "stage1_loads").provenance.checks
    assert "s in force" in checks["FMU simulation timeout"] and "configured 3 s" in checks["FMU simulation timeout"]
    quarantined = checks["FMU points quarantined"]
    assert f"wind_speed {FAULTS['crash']:g}" in quarantined and f"wind_speed {FAULTS['hang']:g}" in quarantined
    assert "TIMEOUT" in quarantined
    assert "FMU points quarantined" in (tmp_path / "out" / "report.html").read_text()
