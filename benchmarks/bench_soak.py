"""Soak: thousands of consecutive steady FMU evaluations with bounded resident memory.

Two runs of variant A (NREL 5-MW, the mapping's default physics and steady window,
16 parameters: 3 pitch offsets, the stall-delay strength and a 3 x 2 correction grid):

- ``one_worker``: ``n_evaluations`` evaluations of one operating point each, one after
  the other, through :class:`~calib.fmu.model.FmuModel` with the serial executor
  and an isolated FMU worker process (the default): the calling process drives, one child
  process holds the FMU instance and simulates.
- ``dask``: the same number of evaluations through
  :class:`~calib.executors.DaskExecutor` (a ``LocalCluster`` of ``dask_workers`` worker
  processes, each with its own FMU worker process), in batches of ``batch`` points.

The operating points cycle through 10 points of the operating range (5-13 m/s, rotor speed
7 rpm at 5 m/s rising to 12.1 rpm at 11.4 m/s, pitch 0-4 deg above it) and the parameter
vector changes at every evaluation (one-worker run) or batch (Dask run), seeded, within half
a scale of nominal, so every evaluation sets new values.

Resident memory (RSS, through ``psutil``, which ``dask.distributed`` already depends on)
is read after ``warmup`` evaluations and at the end, in every process that takes part:
the calling process and its FMU worker process; each Dask worker (``client.run``) and the
FMU worker process under it. Figures: evaluations per second, RSS warm / end [MiB] and
the growth [%] of each process, the largest growth, the number of non-OK statuses and of
worker restarts, and an RSS trace every ``trace_every`` evaluations.

Limits (``run()`` returns an ``"error"`` and the script exits 1 when one is broken):

- RSS growth from the end of the warm-up to the end below ``RSS_GROWTH_LIMIT`` (10 %) in
  every process;
- no non-OK status and no worker restart (a restarted worker would also reset its RSS and
  hide a leak).

``--fast`` uses a cheap window (8 steps per revolution, no settling, 2 revolutions
averaged) and quasi-steady physics: the same code paths at ~1/10 of the cost, for
``tests/test_soak.py``. ``--leak-kib K`` keeps K KiB per evaluation alive in the calling
process: a deliberate leak that must break the limit (the test proves the check can fail).

Usage: ``python benchmarks/bench_soak.py [--evaluations 2000] [--warmup 200] [--fast]
[--no-dask] [--json FILE]``; ``make bench`` runs it with the defaults.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

#: A statistical or soak study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

ROOT = Path(__file__).resolve().parents[1]
RSS_GROWTH_LIMIT = 0.10
CHANNELS = ["power", "thrust", "root_flap_moment"]
GRID_ALPHA_DEG, GRID_ETA = [0.0, 5.0, 10.0], [0.4, 0.9]
# cheap variant: the fast settings of tests/test_fmu_model.py
FAST_SWITCHES = dict(tower_shadow=False, shear=False, yaw=False, flexible_blades=False, gravity=False,
                     dynamic_inflow=False, stall_delay=False, skewed_wake=False, tip_loss=True, hub_loss=True)
FAST_SETTINGS = {"shaft_tilt": 0.0, "max_internal_step": 0.1, "max_azimuth_step": 10.0}
FAST_WINDOW = dict(steps_per_revolution=8, settle_revolutions=0, average_revolutions=2)
MIB = 1024.0 * 1024.0


# ----------------------------------------------------------------------------- memory
def process_memory() -> dict:
    """RSS [bytes] of this process and of each of its child processes, by pid.

    Module-level and free of benchmark globals so that ``client.run`` can call it on a
    Dask worker (it is shipped by value, see :func:`soak_dask`).
    """
    import os as _os

    import psutil
    me = psutil.Process()
    children = {}
    for child in me.children(recursive=True):
        try:
            children[child.pid] = int(child.memory_info().rss)
        except psutil.NoSuchProcess:       # ended between listing and reading
            pass
    return {"pid": _os.getpid(), "rss": int(me.memory_info().rss), "children": children}


def _growth(warm: dict, end: dict, label: str, tag: str, children=None) -> list[dict]:
    """Per-process rows from two :func:`process_memory` readings: the process, then its children.

    ``children`` (pids) limits the children to those; a child present at the end but not
    after warm-up (a restarted FMU worker) has no warm reading: its growth is NaN, which
    breaks the limit.
    """
    rows = [{"process": label, "tag": tag, "pid": warm["pid"], "rss_warm": warm["rss"], "rss_end": end["rss"]}]
    pids = sorted(end["children"] if children is None else children)
    for n, pid in enumerate(pids):
        rows.append({"process": f"{label}: FMU worker process", "tag": f"{tag}_fmu" + (f"{n}" if n else ""),
                     "pid": pid, "rss_warm": warm["children"].get(pid, np.nan), "rss_end": end["children"][pid]})
    for row in rows:
        row["growth"] = (row["rss_end"] - row["rss_warm"]) / row["rss_warm"]
    return rows


# ----------------------------------------------------------------------------- set-up
def _fmu():
    from calib.corrections import CorrectionGrid
    from calib.fmu.build import build_fmu
    return build_fmu("A", None, CorrectionGrid(GRID_ALPHA_DEG, GRID_ETA))


def _model(path, fast: bool, executor=None):
    from calib.fmu.build import mapping_path
    from calib.fmu.model import FmuModel
    opts = dict(switches=FAST_SWITCHES, settings=FAST_SETTINGS, steady=FAST_WINDOW) if fast else {}
    return FmuModel(path, mapping_path("A"), CHANNELS, executor=executor, **opts)


def _schedule(model, n_evaluations: int, seed: int = 1):
    """Operating conditions (10 points of the range, cycled) and parameter vectors, one per evaluation."""
    from calib.types import OperatingConditions
    wind = np.array([5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 11.4, 12.0, 13.0])
    rpm = np.clip(7.0 + (12.1 - 7.0) * (wind - 5.0) / (11.4 - 5.0), 7.0, 12.1)
    pitch = np.where(wind > 11.4, 4.0 * (wind - 11.4) / 1.6, 0.0)
    k = np.arange(n_evaluations) % len(wind)
    conditions = OperatingConditions(wind[k], rpm[k], pitch[k])
    q = model.parameters
    nominal = np.array([x.nominal for x in q])
    scale = np.array([x.scale for x in q])
    rng = np.random.default_rng(seed)
    p = nominal + 0.5 * scale * rng.uniform(-1.0, 1.0, (n_evaluations, len(q)))
    p = np.clip(p, [x.lower for x in q], [x.upper for x in q])
    return conditions, p


def _check(out: dict, rows: list[dict], prefix: str) -> list[str]:
    """Store the rows' figures (``<prefix><tag>_rss_*``) and return the broken limits."""
    broken = []
    for row in rows:
        tag = prefix + row["tag"]
        out[f"{tag}_rss_warm_mib"] = row["rss_warm"] / MIB
        out[f"{tag}_rss_end_mib"] = row["rss_end"] / MIB
        out[f"{tag}_rss_growth_percent"] = 100.0 * row["growth"]
        if not row["growth"] < RSS_GROWTH_LIMIT:
            broken.append(f"{row['process']} (pid {row['pid']}): RSS {row['rss_warm'] / MIB:.1f} -> "
                          f"{row['rss_end'] / MIB:.1f} MiB ({100 * row['growth']:+.1f} %, limit "
                          f"{100 * RSS_GROWTH_LIMIT:g} %)")
    out[f"{prefix}max_rss_growth_percent"] = 100.0 * max(r["growth"] for r in rows)
    return broken


# ----------------------------------------------------------------------------- runs
def soak_one_worker(path, n_evaluations: int, warmup: int, fast: bool, leak_kib: int = 0,
                    trace_every: int = 100) -> tuple[dict, list[str]]:
    """Consecutive one-point evaluations: this process and its one FMU worker process."""
    model = _model(path, fast)
    conditions, p = _schedule(model, n_evaluations)
    earlier = set(process_memory()["children"])      # processes started before this run are not its worker
    ballast = []
    failed = restarts = 0
    warm = None
    trace = []
    t_warm = time.perf_counter()
    try:
        for k in range(n_evaluations):
            ev = model.evaluate(p[k], conditions.subset([k]))
            failed += ev.n_failed
            restarts += int(np.sum(ev.extras["restarts"]))
            if leak_kib:
                ballast.append(b"\x01" * (leak_kib * 1024))
            if k + 1 == warmup:
                warm, t_warm = process_memory(), time.perf_counter()
            if (k + 1) % trace_every == 0:
                mem = process_memory()
                trace.append([k + 1, mem["rss"] / MIB] + [mem["children"][c] / MIB for c in sorted(mem["children"])
                                                          if c not in earlier])
                print(f"[soak] one worker: {k + 1}/{n_evaluations} evaluations, RSS (MiB) calling process, "
                      f"FMU worker: {', '.join(f'{x:.1f}' for x in trace[-1][1:])}", file=sys.stderr, flush=True)
        t_end = time.perf_counter()
        end = process_memory()
    finally:
        model.close()
    workers = [c for c in end["children"] if c not in earlier]
    rows = _growth(warm, end, "one worker: calling process", "driver", workers)
    out = {"one_worker_evaluations": n_evaluations, "one_worker_warmup_evaluations": warmup,
           "one_worker_evaluations_per_s": (n_evaluations - warmup) / (t_end - t_warm),
           "one_worker_fmu_worker_processes": len(workers),
           "one_worker_non_ok_statuses": failed, "one_worker_worker_restarts": restarts,
           "one_worker_rss_trace_mib": trace}
    broken = _check(out, rows, "one_worker_")
    if len(workers) != 1:
        broken.append(f"one worker: expected 1 FMU worker process, found {len(workers)}")
    if failed or restarts:
        broken.append(f"one worker: {failed} non-OK statuses, {restarts} worker restarts")
    return out, broken


def soak_dask(path, n_evaluations: int, warmup: int, fast: bool, workers: int = 2,
              batch: int = 20, trace_every: int = 100) -> tuple[dict, list[str]]:
    """The same evaluations through the Dask executor, in batches of ``batch`` points."""
    import cloudpickle

    from calib.executors import DaskExecutor

    if warmup % batch or n_evaluations % batch:
        raise ValueError(f"warmup ({warmup}) and evaluations ({n_evaluations}) must be multiples of batch ({batch})")
    cloudpickle.register_pickle_by_value(sys.modules[process_memory.__module__])   # workers cannot import this file
    failed = restarts = 0
    trace = []
    with DaskExecutor(workers=workers) as dask:
        model = _model(path, fast, executor=dask)
        conditions, p = _schedule(model, n_evaluations)
        warm = None
        t0 = t_warm = time.perf_counter()
        for start in range(0, n_evaluations, batch):
            # one call evaluates `batch` points at one parameter vector
            ev = model.evaluate(p[start], conditions.subset(list(range(start, start + batch))))
            failed += ev.n_failed
            restarts += int(np.sum(ev.extras["restarts"]))
            if start + batch == warmup:
                warm, t_warm = dask.client.run(process_memory), time.perf_counter()
            if (start + batch) % trace_every == 0:
                mem = dask.client.run(process_memory)
                trace.append([start + batch] + [mem[a]["rss"] / MIB for a in sorted(mem)])
                print(f"[soak] dask: {start + batch}/{n_evaluations} evaluations, RSS (MiB) of the workers: "
                      f"{', '.join(f'{x:.1f}' for x in trace[-1][1:])}", file=sys.stderr, flush=True)
        t_end = time.perf_counter()
        end = dask.client.run(process_memory)
        model.close()
    rows = []
    for n, address in enumerate(sorted(end)):
        rows += _growth(warm[address], end[address], f"dask worker {n}", f"worker{n}")
    out = {"dask_workers": workers, "dask_batch_points": batch, "dask_evaluations": n_evaluations,
           "dask_warmup_evaluations": warmup,
           "dask_evaluations_per_s": (n_evaluations - warmup) / (t_end - t_warm),
           "dask_startup_and_warmup_s": t_warm - t0,
           "dask_fmu_worker_processes": sum(len(end[a]["children"]) for a in end),
           "dask_non_ok_statuses": failed, "dask_worker_restarts": restarts, "dask_rss_trace_mib": trace}
    broken = _check(out, rows, "dask_")
    if failed or restarts:
        broken.append(f"dask: {failed} non-OK statuses, {restarts} worker restarts")
    return out, broken


def soak(n_evaluations: int = 2000, warmup: int = 200, fast: bool = False, dask: bool = True,
         dask_workers: int = 2, leak_kib: int = 0) -> dict:
    """Both soak runs in this process; ``"error"`` names every broken limit."""
    if not 0 < warmup < n_evaluations:
        raise ValueError(f"warmup must be between 0 and the number of evaluations, got {warmup} of {n_evaluations}")
    path = _fmu()
    out = {"rss_growth_limit_percent": 100 * RSS_GROWTH_LIMIT, "fast_variant": fast}
    figures, broken = soak_one_worker(path, n_evaluations, warmup, fast, leak_kib)
    out.update(figures)
    if dask:
        figures, more = soak_dask(path, n_evaluations, warmup, fast, dask_workers)
        out.update(figures)
        broken += more
    if broken:
        out["error"] = "; ".join(broken)
    return out


def run(n_evaluations: int = 2000, warmup: int = 200) -> dict:
    """``make bench``: :func:`soak` in a fresh process (the RSS of a process that ran the
    other benchmarks says little), figures read back from its JSON file."""
    import subprocess
    import tempfile

    with tempfile.TemporaryDirectory(prefix="bench-soak-") as tmp:
        dest = Path(tmp) / "soak.json"
        done = subprocess.run([sys.executable, __file__, "--evaluations", str(n_evaluations), "--warmup", str(warmup),
                               "--json", str(dest)], capture_output=True, text=True, cwd=ROOT)
        if not dest.is_file():
            return {"error": f"soak process failed (exit {done.returncode}): {done.stderr.strip()[-800:]}"}
        return json.loads(dest.read_text())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--evaluations", type=int, default=2000)
    ap.add_argument("--warmup", type=int, default=200)
    ap.add_argument("--fast", action="store_true", help="cheap window and quasi-steady physics (the test's variant)")
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask run")
    ap.add_argument("--dask-workers", type=int, default=2)
    ap.add_argument("--leak-kib", type=int, default=0, help="keep this many KiB per evaluation alive (self-check)")
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    args = ap.parse_args(argv)
    res = soak(args.evaluations, args.warmup, args.fast, not args.no_dask, args.dask_workers, args.leak_kib)
    for key, value in res.items():
        if isinstance(value, list):
            continue
        print(f"{key:45s} {value:.4g}" if isinstance(value, float) else f"{key:45s} {value}", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1, default=float))
    return 1 if "error" in res else 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
