"""`make bench` and `make validate`: run the ``benchmarks/bench_*.py`` of a suite, print one table.

Two suites. ``speed`` (``make bench``, the default; a few minutes): the speed figures, each
a ratio against a baseline measured in the same run. ``validate`` (``make validate``; an
hour or more): the statistical and soak studies, the modules that declare
``SUITE = "validate"`` (coverage of the calibration twins over 30 seeds, the discrepancy
workflow over noise seeds, Phase VI's sensitivity to the noise model, the 2000-evaluation
FMU soak). ``--suite all`` runs both.

Order: ``bench_bem``, ``bench_ccblade``, ``bench_calibration``, ``bench_fmu`` (those that
exist), then any other ``bench_*.py`` alphabetically. Each module's ``run()`` returns a
dict of figures (scalars, strings, arrays); a dict with an ``"error"`` key, or an
exception, marks the module as failed: it is reported and the others still run.
``bench_ccblade.run`` gets the native surface's grid when ``bench_bem`` returned one,
so both codes evaluate exactly the same points.

Ratios printed (and stored):

- native throughput / CCBlade throughput on the C_P(λ, β) surface, in points per
  second (target >= 100);
- Jacobian time / one evaluation time (target <= 3);
- max |ΔC_P| between the native and CCBlade surfaces over the points where both
  converged (native mask: ``converged`` if returned, else finite ``cp``);
- FMU faults (``bench_fmu_faults``): a calibration through an FMU with a crashing, a hanging
  and an erroring point over the same calibration without the faults (target <= 3);
- soak (``bench_soak``): the largest resident-memory growth after warm-up over the
  processes of 2000 FMU evaluations, in one worker and through Dask (target < 10 %).

Writes ``bench_output/results.json`` (speed), ``bench_output/validation.json`` (validate) or
``bench_output/all.json``. Exit status 1 when a module failed.
"""

from __future__ import annotations

import glob
import importlib
import inspect
import json
import math
import os
import platform
import sys
import time
import traceback

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
OUT_DIR = os.path.join(ROOT, "bench_output")
ORDER = ["bench_bem", "bench_ccblade", "bench_calibration", "bench_fmu"]

TARGET_THROUGHPUT_RATIO = 100.0   # issue 38
TARGET_JACOBIAN_RATIO = 3.0
TARGET_SOAK_GROWTH_PERCENT = 10.0


SUITES = ("speed", "validate", "all")
OUT_FILES = {"speed": "results.json", "validate": "validation.json", "all": "all.json"}


def suite_of(name: str) -> str:
    """The suite a benchmark module declares (``SUITE = "validate"``), read without importing it."""
    with open(os.path.join(HERE, f"{name}.py")) as fh:
        for line in fh:
            if line.startswith("SUITE ="):
                return line.split("=", 1)[1].strip().strip("\"'")
    return "speed"


def discover(suite: str = "speed") -> list[str]:
    found = {os.path.basename(p)[:-3] for p in glob.glob(os.path.join(HERE, "bench_*.py"))}
    found = {m for m in found if suite == "all" or suite_of(m) == suite}
    return [m for m in ORDER if m in found] + sorted(found - set(ORDER))


def run_module(name: str, kwargs: dict) -> tuple[dict, float]:
    t0 = time.perf_counter()
    try:
        mod = importlib.import_module(name)
        fn = getattr(mod, "run", None)
        if fn is None:
            return {"error": f"{name}.py has no run()"}, time.perf_counter() - t0
        params = inspect.signature(fn).parameters
        res = fn(**{k: v for k, v in kwargs.items() if k in params})
        if not isinstance(res, dict):
            res = {"error": f"{name}.run() returned {type(res).__name__}, not a dict"}
    except Exception as exc:  # noqa: BLE001  (one failing module must not stop the others)
        tb = traceback.format_exc().strip().splitlines()
        res = {"error": f"{type(exc).__name__}: {exc}", "traceback": "\n".join(tb[-12:])}
    return res, time.perf_counter() - t0


# ----------------------------------------------------------------------------- helpers
def _num(v) -> float | None:
    if isinstance(v, (bool, np.bool_)):
        return None
    if isinstance(v, (int, float, np.integer, np.floating)):
        return float(v)
    return None


def _fmt(v) -> str:
    x = _num(v)
    if x is None:
        s = str(v)
        return s if len(s) <= 60 else s[:57] + "..."
    if math.isnan(x):
        return "nan"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if x != 0 and (abs(x) >= 1e5 or abs(x) < 1e-3):
        return f"{x:.4g}"
    return f"{x:.4f}" if abs(x) < 10 else f"{x:.2f}"


def _surface(res: dict):
    """(cp, ok) as (n_tsr, n_pitch) arrays, or None."""
    if "cp" not in res or "tsr" not in res or "pitch" not in res:
        return None
    shape = (np.size(res["tsr"]), np.size(res["pitch"]))
    cp = np.asarray(res["cp"], dtype=float)
    if cp.size != shape[0] * shape[1]:
        return None
    cp = cp.reshape(shape)
    ok = np.isfinite(cp)
    if "converged" in res:
        conv = np.asarray(res["converged"], dtype=bool)
        if conv.size == cp.size:
            ok &= conv.reshape(shape)
    return cp, ok


def _points_per_second(res: dict, seconds_key: str):
    s, n = _num(res.get(seconds_key)), _num(res.get("n_points"))
    if s and n and s > 0:
        return n / s
    return None


def compute_ratios(results: dict) -> list[dict]:
    rows = []
    bem = results.get("bench_bem", {})
    cc = results.get("bench_ccblade", {})
    bem_ok = bem and "error" not in bem
    cc_ok = cc and "error" not in cc

    native_pps = _points_per_second(bem, "native_surface_seconds") if bem_ok else None
    cc_pps = _points_per_second(cc, "ccblade_surface_seconds") if cc_ok else None
    rows.append({
        "name": "surface throughput native / CCBlade (points/s)",
        "value": native_pps / cc_pps if native_pps and cc_pps else None,
        "detail": (f"{native_pps:.0f} vs {cc_pps:.0f} points/s" if native_pps and cc_pps
                   else "needs bench_bem and bench_ccblade"),
        "target": f">= {TARGET_THROUGHPUT_RATIO:g}",
        "met": (native_pps / cc_pps >= TARGET_THROUGHPUT_RATIO) if native_pps and cc_pps else None,
    })

    jac, ev = (_num(bem.get("jacobian_seconds")), _num(bem.get("eval_seconds"))) if bem_ok else (None, None)
    rows.append({
        "name": "Jacobian / one evaluation (time)",
        "value": jac / ev if jac and ev else None,
        "detail": (f"{jac:.4g} s vs {ev:.4g} s" + (f", {bem['n_params']} parameters" if "n_params" in bem else "")
                   if jac and ev else "needs bench_bem eval_seconds and jacobian_seconds"),
        "target": f"<= {TARGET_JACOBIAN_RATIO:g}",
        "met": (jac / ev <= TARGET_JACOBIAN_RATIO) if jac and ev else None,
    })

    sa = _surface(bem) if bem_ok else None
    sb = _surface(cc) if cc_ok else None
    value, detail = None, "needs both surfaces on the same grid"
    if sa and sb and sa[0].shape == sb[0].shape and np.allclose(bem["tsr"], cc["tsr"]) \
            and np.allclose(bem["pitch"], cc["pitch"]):
        both = sa[1] & sb[1]
        if both.any():
            d = np.where(both, np.abs(sa[0] - sb[0]), -np.inf)
            i, j = np.unravel_index(np.argmax(d), d.shape)
            value = float(d[i, j])
            med = float(np.median(np.abs(sa[0] - sb[0])[both]))
            ia, ja = np.unravel_index(np.argmax(np.where(sa[1], sa[0], -np.inf)), sa[0].shape)
            ib, jb = np.unravel_index(np.argmax(np.where(sb[1], sb[0], -np.inf)), sb[0].shape)
            detail = (f"at λ={bem['tsr'][i]:.2f}, β={bem['pitch'][j]:.1f}°; median {med:.2g}; "
                      f"{int(both.sum())}/{both.size} points both converged; "
                      f"C_P max native {sa[0][ia, ja]:.4f} (λ={bem['tsr'][ia]:.2f}, β={bem['pitch'][ja]:.1f}°), "
                      f"CCBlade {sb[0][ib, jb]:.4f} (λ={cc['tsr'][ib]:.2f}, β={cc['pitch'][jb]:.1f}°)")
        else:
            detail = "no point converged in both"
    rows.append({"name": "max |ΔC_P| native vs CCBlade", "value": value, "detail": detail,
                 "target": "", "met": None})

    faults = results.get("bench_fmu_faults", {})
    ratio = _num(faults.get("ratio_faulty_over_clean"))
    rows.append({
        "name": "FMU faults: calibration with a crashing, a hanging and an erroring point / without (time)",
        "value": ratio,
        "detail": (f"{_fmt(faults.get('faulty_total_s'))} s vs {_fmt(faults.get('clean_total_s'))} s at "
                   f"{_fmt(1e3 * faults.get('step_cost_s', 0.0))} ms per FMU step; at the toy FMU's own speed "
                   f"{_fmt(faults.get('natural_faulty_total_s'))} s vs {_fmt(faults.get('natural_clean_total_s'))} s "
                   f"({_fmt(faults.get('natural_ratio_faulty_over_clean'))}x)" if ratio is not None
                   else "needs bench_fmu_faults"),
        "target": "<= 3", "met": (ratio <= 3.0) if ratio is not None else None,
    })

    soak = results.get("bench_soak", {})
    growth = [_num(soak.get(f"{k}_max_rss_growth_percent")) for k in ("one_worker", "dask")]
    growth = [g for g in growth if g is not None]
    rows.append({
        "name": "soak: largest RSS growth after warm-up (%)",
        "value": max(growth) if growth else None,
        "detail": (f"one worker {soak.get('one_worker_evaluations')} evaluations, "
                   f"{_fmt(soak.get('one_worker_evaluations_per_s'))}/s; Dask "
                   f"{soak.get('dask_evaluations')}, {_fmt(soak.get('dask_evaluations_per_s'))}/s; "
                   f"non-OK {soak.get('one_worker_non_ok_statuses')} + {soak.get('dask_non_ok_statuses')}"
                   if growth else "needs bench_soak"),
        "target": f"< {TARGET_SOAK_GROWTH_PERCENT:g}",
        "met": (max(growth) < TARGET_SOAK_GROWTH_PERCENT) if growth else None,
    })
    return rows


def print_report(order, results, seconds, ratios) -> None:
    w = 58
    print()
    print("=" * 100)
    print("Benchmarks")
    print("=" * 100)
    for name in order:
        res = results[name]
        status = "FAILED" if "error" in res else "ok"
        print(f"\n[{name}]  {status}  ({seconds[name]:.1f} s wall)")
        if "error" in res:
            for line in str(res["error"]).splitlines():
                print(f"    {line}")
            if "traceback" in res:
                for line in res["traceback"].splitlines():
                    print(f"      {line}")
        for key, v in res.items():
            if key in ("error", "traceback") or isinstance(v, (np.ndarray, list, tuple, dict)):
                continue
            print(f"    {key:<{w}} {_fmt(v)}")
    print("\n" + "-" * 100)
    print("Ratios")
    print("-" * 100)
    for row in ratios:
        val = "n/a" if row["value"] is None else (f"{row['value']:.3g}")
        met = {True: "met", False: "NOT met", None: ""}[row["met"]]
        tgt = f"target {row['target']}" if row["target"] else ""
        print(f"  {row['name']:<50} {val:>10}  {tgt:<14} {met}")
        print(f"      {row['detail']}")
    print("=" * 100)


def _jsonable(v):
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())
    if isinstance(v, (np.bool_, bool)):
        return bool(v)
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if v is None or isinstance(v, (int, str)):
        return v
    return str(v)


def publish_speed(doc: dict) -> str:
    """The speed figures the documentation renders (``docs/validation/data/speed.json``, with the date,
    the commit and the command: :mod:`publish`), with the machine: the ratios, and the calibration's
    times per size."""
    from publish import publish

    res = doc["results"]
    cal, scaling = res.get("bench_calibration", {}), res.get("bench_scaling", {})
    figures = {"machine": doc["machine"], "ratios": doc["ratios"],
               "calibration": {k: cal[k] for k in ("calibration_map_seconds", "calibration_map_model_jacobians",
                                                   "calibration_seconds", "calibration_model_jacobians",
                                                   "calibration_params", "calibration_points") if k in cal},
               "scaling": {k: v for k, v in scaling.items() if isinstance(v, dict)},
               "ccblade": {k: v for k, v in res.get("bench_ccblade", {}).items() if k.startswith("smoothed_native_")},
               "fmu": {k: v for k, v in res.get("bench_fmu", {}).items() if k.endswith("_realtime_factor")}}
    return publish("speed", _jsonable(figures), "make bench")


def main(argv=None) -> int:
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--suite", choices=SUITES, default="speed", help="speed (make bench, default), validate "
                        "(make validate: statistical and soak studies) or all")
    suite = parser.parse_args(argv).suite
    sys.path.insert(0, HERE)
    sys.path.insert(0, ROOT)
    order = discover(suite)
    print(f"{suite} suite: {', '.join(order)}", flush=True)
    results, seconds = {}, {}
    for name in order:
        kwargs = {}
        bem = results.get("bench_bem", {})
        if name == "bench_ccblade" and "error" not in bem and "tsr" in bem and "pitch" in bem:
            from surface_grid import surface_grid  # noqa: PLC0415
            kwargs["grid"] = (np.asarray(bem["tsr"]), np.asarray(bem["pitch"]),
                              bem.get("rotor_speed_rpm", surface_grid()[2]))
        print(f"running {name} ...", flush=True)
        results[name], seconds[name] = run_module(name, kwargs)
    # a suite states only the ratios of its own modules
    needs = {"soak": "bench_soak", "FMU faults": "bench_fmu_faults"}
    ratios = [r for r in compute_ratios(results)
              if needs.get(r["name"].split(":")[0], "bench_bem") in order]
    print_report(order, results, seconds, ratios)

    os.makedirs(OUT_DIR, exist_ok=True)
    failed = [n for n in order if "error" in results[n]]
    doc = {
        "suite": suite,
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "processor": platform.processor(), "cpu_count": os.cpu_count()},
        "modules": order,
        "failed": failed,
        "wall_seconds": seconds,
        "ratios": ratios,
        "results": results,
    }
    path = os.path.join(OUT_DIR, OUT_FILES[suite])
    with open(path, "w") as fh:
        json.dump(_jsonable(doc), fh, indent=1)
    print(f"wrote {os.path.relpath(path, os.getcwd())}")
    if suite == "speed":
        print(f"wrote {os.path.relpath(publish_speed(doc), os.getcwd())}")
    if failed:
        print(f"failed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
