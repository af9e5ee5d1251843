"""A faulty vendor FMU against the same FMU with its faults off: the unit check and a calibration.

The FMU is the PythonFMU test rotor ``tests/data/fmu/FaultyRotor.py`` (4 tuning parameters:
C_P and C_T gains, pitch bias, tip speed ratio of the power peak), built here. 48 operating
points along a power curve (5-12 m/s); measurements synthesized by the fault-free model at
known parameters, 1 % noise. The faulty run switches on, at one point each: a crash
(``abort()``), a hang (``do_step`` never returns) and an error status (a refused step,
``fmi2Discard``); the clean run simulates the same FMU with the faults off. Both run, in this
process and this order: :func:`calib.checks.unit_check.check_units` at the nominal parameters, then
:func:`calib.calibration.calibrator.calibrate` (``retain="all"``, known noise), with the model's default
timeout (60 s) and the serial executor. ``step_cost`` [s] of busy work per FMU step gives a
healthy simulation the cost of a real aeroelastic FMU: the default, 0.16 ms (about 5 ms per
cold run, 2 s per Jacobian of the 48 points), makes the clean run cost about what the clean
calibration of issue 24's vendor FMU cost (41.5 s); with 0 the runs cost 0.5 ms and the fixed
cost of the faults (a 5 s timeout per hang, a new process per crash) dominates the ratio. Both
are reported: the gated figures at ``step_cost``, and ``natural_*`` at step cost 0 (not gated:
a toy FMU's clean calibration of a few seconds is shorter than one timeout floor).

Figures: wall times [s] of each phase and run, their difference (the cost of the faults),
the ratio faulty / clean (acceptance: <= ``ACCEPT_RATIO``), the simulations that met each
fault (counted by the FMU itself through
``$FAULTY_ROTOR_LOG``, in total and per operating point), the model's
:meth:`~calib.fmu.model.FmuModel.fault_summary` (timeout in force, quarantined
points), and the largest difference of the estimates, faulty - clean, in clean standard
deviations (the faulty run has 45 usable points, the clean one 48).

``run()`` returns an ``"error"`` (and the script exits 1) when the ratio exceeds the
acceptance or a crashing or hanging point is simulated more than twice in the calibration.

Usage: ``python benchmarks/bench_fmu_faults.py [--step-cost 0.00016] [--json FILE]``; writes
``bench_output/bench_fmu_faults.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "fmu"
OUT = ROOT / "bench_output" / "bench_fmu_faults.json"
ACCEPT_RATIO = 3.0
N_POINTS = 48
FAULT_INDEX = {"crash": 11, "hang": 23, "error": 35}
P_TRUE = (1.06, 0.95, 0.8, 8.6)          # cp_gain, ct_gain, pitch_bias [deg], tsr_opt
STEP_COST = 1.6e-4                       # [s]


def _build(folder: Path) -> Path:
    cmd = [sys.executable, "-m", "pythonfmu", "build", "-f", str(DATA / "FaultyRotor.py"), "--handle-state",
           "--serialize-state", "-d", str(folder)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if done.returncode != 0:
        raise RuntimeError(f"pythonfmu build failed: {done.stderr[-500:]}")
    return folder / "FaultyRotor.fmu"


def _conditions():
    from calib.types import OperatingConditions
    wind = np.round(np.linspace(5.0, 12.05, N_POINTS), 2)
    rpm = np.clip(7.0 + 9.0 * (wind - 5.0) / 6.0, 7.0, 16.0)
    return OperatingConditions(wind, rpm, np.clip(3.0 * (wind - 11.0), 0.0, None))


def _model(fmu: Path, settings: dict):
    from calib.fmu.model import FmuModel
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")            # PythonFMU's empty InitialUnknowns: a finding, not a fault
        return FmuModel(fmu, DATA / "faulty_rotor_mapping.toml", ["power", "thrust"], settings=settings)


def _log_lines(log: Path | None) -> list[str]:
    return log.read_text().splitlines() if log is not None and log.is_file() else []


def _timed_run(model, meas, log: Path | None = None) -> dict:
    """Unit check and calibration through ``model``: wall times [s], the estimate, and the
    number of fault-log lines written before the calibration."""
    from calib.calibration import calibrate
    from calib.checks.unit_check import check_units
    p0 = np.array([q.nominal for q in model.parameters])
    t0 = time.perf_counter()
    check_units(model, p0, meas)
    t1 = time.perf_counter()
    mark = len(_log_lines(log))
    res = calibrate(model, meas, retain="all", noise="known")
    t2 = time.perf_counter()
    return {"unit_check_s": t1 - t0, "calibration_s": t2 - t1, "total_s": t2 - t0, "status": res.estimate.status,
            "failed_points": int(res.fit.failures["final"]), "p_hat": np.array([v["value"] for v in res.identifiability.verdicts]),
            "std": np.array([v["std"] for v in res.identifiability.verdicts]), "log_mark": mark}


def _simulations(log: Path, mark: int) -> dict:
    """Faulty simulations from the FMU's own log (``kind wind rpm pitch pid`` per line): per
    kind, per operating point, and per point in the calibration (lines after ``mark``)."""
    lines = _log_lines(log)
    return {"by_kind": dict(Counter(line.split()[0] for line in lines)),
            "by_point": dict(Counter(" ".join(line.split()[:4]) for line in lines)),
            "calibration_by_point": dict(Counter(" ".join(line.split()[:4]) for line in lines[mark:]))}


def _most_quarantinable(by_point: dict) -> int:
    """Most simulations of one crashing or hanging point (an erroring point is not quarantined)."""
    return max((n for key, n in by_point.items() if key.split()[0] in ("crash", "hang")), default=0)


def _one(fmu: Path, meas, settings: dict, log: Path | None = None) -> tuple[dict, dict]:
    """A timed run through a new model with ``settings``; (figures, fault summary)."""
    if log is not None:
        os.environ["FAULTY_ROTOR_LOG"] = str(log)      # read by the worker processes started below
    model = _model(fmu, settings)
    try:
        return _timed_run(model, meas, log), model.fault_summary()
    finally:
        model.close()
        os.environ.pop("FAULTY_ROTOR_LOG", None)


def run(step_cost: float = STEP_COST, natural: bool = True) -> dict:
    """Figures of the benchmark (see the module docstring); with ``natural`` also the pair at
    the FMU's own speed (step cost 0), reported beside the gated figures, not gated."""
    from calib.measurements import synthesize
    cond = _conditions()
    with tempfile.TemporaryDirectory(prefix="bench_fmu_faults-") as tmp:
        fmu = _build(Path(tmp))
        truth = _model(fmu, {})
        meas = synthesize(truth, np.array(P_TRUE), cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=24)
        truth.close()
        out = _figures(*_pair(fmu, meas, cond, step_cost, Path(tmp)), step_cost)
        if natural and step_cost > 0:
            clean, faulty, *_ = _pair(fmu, meas, cond, 0.0, Path(tmp))
            out.update(natural_clean_total_s=clean["total_s"], natural_faulty_total_s=faulty["total_s"],
                       natural_fault_cost_s=faulty["total_s"] - clean["total_s"],
                       natural_ratio_faulty_over_clean=faulty["total_s"] / clean["total_s"])
    return out


def _pair(fmu: Path, meas, cond, step_cost: float, tmp: Path):
    """(clean, faulty, simulations, faulty summary, clean summary) at one step cost."""
    base = {"step_cost": float(step_cost)}
    faults = {**base, **{f"{k}_wind_speed": float(cond.wind_speed[i]) for k, i in FAULT_INDEX.items()}}
    clean, clean_summary = _one(fmu, meas, base)
    log = tmp / f"faults-{step_cost:g}.log"
    faulty, summary = _one(fmu, meas, faults, log)
    return clean, faulty, _simulations(log, faulty["log_mark"]), summary, clean_summary


def _figures(clean, faulty, sims, summary, clean_summary, step_cost) -> dict:
    ratio = faulty["total_s"] / clean["total_s"]
    most = _most_quarantinable(sims["calibration_by_point"])
    out = {"n_points": N_POINTS, "n_parameters": len(P_TRUE), "step_cost_s": step_cost,
           "clean_unit_check_s": clean["unit_check_s"], "clean_calibration_s": clean["calibration_s"],
           "clean_total_s": clean["total_s"], "faulty_unit_check_s": faulty["unit_check_s"],
           "faulty_calibration_s": faulty["calibration_s"], "faulty_total_s": faulty["total_s"],
           "fault_cost_s": faulty["total_s"] - clean["total_s"], "ratio_faulty_over_clean": ratio, "ratio_calibration_only": faulty["calibration_s"] / clean["calibration_s"],
           "acceptance_ratio": ACCEPT_RATIO, "acceptance_met": bool(ratio <= ACCEPT_RATIO),
           "clean_status": clean["status"], "faulty_status": faulty["status"],
           "clean_failed_points": clean["failed_points"], "faulty_failed_points": faulty["failed_points"],
           "max_estimate_shift_in_clean_std": float(np.max(np.abs(faulty["p_hat"] - clean["p_hat"]) / clean["std"])),
           "healthy_median_run_s": clean_summary["timeout"]["median_healthy_s"],
           "timeout_in_force_s": summary["timeout"]["in_force_s"],
           "max_simulations_of_a_crashing_or_hanging_point_in_calibration": most}
    for kind in ("crash", "hang", "error"):
        out[f"faulty_simulations_{kind}"] = sims["by_kind"].get(kind, 0)
    out["faulty_simulations_by_point"] = sims["by_point"]
    out["faulty_simulations_in_calibration_by_point"] = sims["calibration_by_point"]
    out["fault_summary"] = summary
    problems = []
    if ratio > ACCEPT_RATIO:
        problems.append(f"faulty / clean = {ratio:.2f} > {ACCEPT_RATIO:g}")
    if most > 2:
        problems.append(f"a crashing or hanging point was simulated {most} times in the calibration (at most 2 "
                        "expected)")
    if problems:
        out["error"] = "; ".join(problems)
    return out


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_jsonable(x) for x in v]
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return v.item()
    return v


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--step-cost", type=float, default=STEP_COST, help="busy work per FMU step [s]")
    ap.add_argument("--json", type=Path, default=OUT, help=f"output file (default {OUT.relative_to(ROOT)})")
    args = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    res = run(args.step_cost)
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(_jsonable(res), indent=1))
    for key, value in res.items():
        if not isinstance(value, dict):
            print(f"{key:52s} {value:.4g}" if isinstance(value, float) else f"{key:52s} {value}")
    print(f"wrote {args.json}")
    return 1 if "error" in res else 0


if __name__ == "__main__":
    sys.exit(main())
