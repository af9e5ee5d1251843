"""Where users wait on an FMU (issue 38): ``calib run`` and ``calib diagnose`` through the bundled FMU, wall clock
against the issue's targets, on the process pool and on a Dask LocalCluster, for the speed page.

Two studies of their own benchmarks, run back to back in one process so that they see the same machine:

- ``calib run`` of :mod:`bench_fmu_run` (variant A with Øye inflow, 4 parameters, 48 points, 4 channels, 2
  workers), target ≤ 20 s wall;
- ``calib diagnose`` of :mod:`bench_fmu_diagnosis` (variant A, noise seed 0): the control, target ≤ 1 min,
  and the named effects (``pitch_offset_blade1``, ``stall_delay_strength``), target ≤ 3 min each, the verdict
  unchanged (the control ``none``, a named data set its own parameter).

Each row states the simulations, the busy worker seconds and the parallel efficiency (busy / (wall × 2
workers)): the physical limit of a row is its busy worker seconds over 2 workers, which the efficiency
compares the wall with. The machine's load average before and after each row is published beside it: a wall
clock is a figure of an idle machine only when the load says so.

``python benchmarks/bench_fmu_speed.py [process|dask|both]`` (default ``both``: every row on the process pool,
the run, the control and ``pitch_offset_blade1`` on Dask as well); writes ``bench_output/fmu_speed.json`` and
publishes ``docs/validation/data/fmu_speed.json`` (the speed page). Under ``make validate`` :func:`run`.
Several minutes of simulation on 2 workers: a study, not a ``make bench`` figure.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_fmu_diagnosis  # noqa: E402
import bench_fmu_run  # noqa: E402

#: A study of minutes: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

ROOT = HERE.parent
OUT_JSON = ROOT / "bench_output" / "fmu_speed.json"
WORKERS = 2
#: Wall-clock targets of issue 38 [s].
TARGETS = {"run": 20.0, "control": 60.0, "named": 180.0}
#: The diagnosis data sets and the verdict each must keep.
DIAGNOSES = {"control": "none", "pitch_offset_blade1": "pitch_offset_blade1",
             "stall_delay_strength": "stall_delay_strength"}
#: Rows repeated on Dask with ``both``.
DASK_ROWS = ("run", "control", "pitch_offset_blade1")


def _load() -> float:
    """The 1-minute load average [processes]."""
    return float(os.getloadavg()[0])


def _run_row(executor: str) -> dict:
    out = ROOT / "bench_output" / "fmu_speed" / f"run_{executor}"
    wf = bench_fmu_run.prepare(out, executor)
    load0 = _load()
    fig = bench_fmu_run.run_once(wf, out / "run1")
    busy = _busy_from_checks(fig["checks"])
    return {"what": "calib run (48 points, 4 parameters)", "executor": executor, "wall_s": fig["wall_s"],
            "simulations": fig["simulations"], "busy_worker_s": busy, "target_s": TARGETS["run"],
            "verdict": fig["map_status"], "right": fig["map_status"] == "converged",
            "load_before": load0, "load_after": _load()}


def _busy_from_checks(checks: dict) -> float | None:
    """Busy worker seconds from the result's FMU check line (``... s busy on N worker(s) ...``)."""
    import re
    text = next((v for k, v in checks.items() if k.startswith("FMU simulations and")), "")
    m = re.search(r"([\d.e+]+) s busy", text)
    return float(m.group(1)) if m else None


def _diagnosis_row(data_set: str, executor: str) -> dict:
    load0 = _load()
    res = bench_fmu_diagnosis.case("A", data_set, 0, executor)
    tot = res["totals"]
    kind = "control" if data_set == "control" else "named"
    effect = res["effect"]
    return {"what": f"calib diagnose: {data_set.replace('_', ' ')}", "executor": executor, "wall_s": res["wall_s"],
            "simulations": tot.get("simulations"), "busy_worker_s": tot.get("busy_worker_s"),
            "target_s": TARGETS[kind], "verdict": effect, "right": _right(effect, res.get("effects"), data_set),
            "load_before": load0, "load_after": _load()}


def _right(effect: str, effects, data_set: str) -> bool:
    """The benchmark's rule: ``none`` on the control; the data set's parameter, or ``ambiguous`` with it."""
    want = DIAGNOSES[data_set]
    return effect == want or (effect == "ambiguous" and want in json.dumps(effects, default=str))


def markdown(rows: list[dict]) -> str:
    """The published table: one row per measured wall clock."""
    lines = ["| what | executor | wall [s] (target) | simulations | busy / (wall × 2) | verdict | load before / after |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        eff = (f"{r['busy_worker_s'] / (r['wall_s'] * WORKERS):.2f}" if r.get("busy_worker_s") and r["wall_s"] > 0
               else "–")
        lines.append(f"| {r['what']} | {r['executor']} | {r['wall_s']:.1f} (≤ {r['target_s']:g}"
                     f"{'' if r['met'] else ': **not met**'}) | {r['simulations']} | {eff} | {r['verdict']}"
                     f"{'' if r['right'] else ' (**wrong**)'} | {r['load_before']:.1f} / {r['load_after']:.1f} |")
    return "\n".join(lines) + "\n"


def run(executors: str = "both") -> dict:
    """Every row, then the JSON and the published table; returns the figures (``run_all``)."""
    rows = []
    kinds = ("process", "dask") if executors == "both" else (executors,)
    for executor in kinds:
        wanted = ["run", *DIAGNOSES] if executor == "process" or executors != "both" else list(DASK_ROWS)
        for name in wanted:
            print(f"[bench_fmu_speed] {name} on {executor} ...", flush=True)
            row = _run_row(executor) if name == "run" else _diagnosis_row(name, executor)
            row["met"] = bool(row["right"] and row["wall_s"] <= row["target_s"])
            print(f"[bench_fmu_speed]   {row['wall_s']:.1f} s (target {row['target_s']:g} s), {row['simulations']} "
                  f"simulations, {row['verdict']}, load {row['load_before']:.1f} -> {row['load_after']:.1f}",
                  flush=True)
            rows.append(row)
    figures = {"workers": WORKERS, "rows": rows, "all_met": all(r["met"] for r in rows),
               "cpu_count": os.cpu_count()}
    OUT_JSON.parent.mkdir(parents=True, exist_ok=True)
    OUT_JSON.write_text(json.dumps(figures, indent=1))
    from publish import command_line, publish
    publish("fmu_speed", figures, command_line(), markdown(rows))
    return figures


if __name__ == "__main__":
    t0 = time.perf_counter()
    run(sys.argv[1] if len(sys.argv) > 1 else "both")
    print(f"[bench_fmu_speed] done in {time.perf_counter() - t0:.0f} s")
