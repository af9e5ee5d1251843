"""Benchmark (c): the NREL 5-MW C_P(λ, β) surface computed by WISDEM's CCBlade.

Runs in the MAIN venv. CCBlade lives in a separate environment (``.bench-venv``,
made by ``ccblade_env.sh``; never a calib dependency): this module ensures that
environment, exports the calib rotor to JSON (``export_rotor.py``), runs
``ccblade_runner.py`` with ``.bench-venv/bin/python`` and reads back the surface and
its timing. ``run()`` never raises: on failure it returns ``{"error": message}``.

Environment: ``CALIB_BENCH_CCBLADE_REPEATS`` (default 3, best time kept),
``CALIB_BENCH_ROTOR`` (default ``nrel5mw``), ``CALIB_BENCH_CCBLADE_SPLINE``
(``ccairfoil``, default: CCAirfoil's smoothing spline as CCBlade always uses it;
``linear``: interpolation through the table points, a diagnostic), plus those of
``ccblade_env.sh``.

With CCAirfoil's spline, the native BEM is also run on the same grid with the same
smoothing of its polars (``SectionPolars.from_rotor(..., smoothing=CCAIRFOIL_SMOOTHING)``)
and the largest |ΔC_P| to CCBlade is reported: it isolates everything but the polar
treatment. And CCBlade is run at the 50 operating points of the IEA 3.4-MW CCBlade table
that ``tests/test_bem_validation.py`` compares with (same set-up: tilt 5 deg, shear 0.2,
4 sectors), to tell how much of the native-vs-table difference is the table's own
(``iea34_*`` keys).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
VENV = os.environ.get("CALIB_BENCH_VENV", os.path.join(ROOT, ".bench-venv"))
OUT_DIR = os.path.join(ROOT, "bench_output", "ccblade")
RUN_TIMEOUT_S = 3600
CCAIRFOIL_SMOOTHING = (0.01, 0.001)   # WISDEM 4.2.9 CCAirfoil: RectBivariateSpline s on C_L, C_D


def _dir_size_mb(path: str) -> float:
    total = 0
    for base, _, files in os.walk(path):
        for f in files:
            try:
                total += os.lstat(os.path.join(base, f)).st_size
            except OSError:
                pass
    return total / 2**20


def _tail(text: str, n: int = 15) -> str:
    lines = [ln for ln in (text or "").splitlines() if "WARNING: Location" not in ln]
    return "\n".join(lines[-n:])


def ensure_env() -> dict:
    """Run ``ccblade_env.sh``; returns ``{"env_seconds", "env_log"}`` or ``{"error"}``."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(["bash", os.path.join(HERE, "ccblade_env.sh")], capture_output=True,
                              text=True, timeout=RUN_TIMEOUT_S, env={**os.environ, "CALIB_BENCH_VENV": VENV})
    except (OSError, subprocess.TimeoutExpired) as exc:
        return {"error": f"could not set up the CCBlade environment {VENV}: {exc}"}
    seconds = time.perf_counter() - t0
    log = _tail(proc.stderr + proc.stdout)
    if proc.returncode != 0:
        return {"error": f"could not install WISDEM's CCBlade into {VENV} "
                         f"(benchmarks/ccblade_env.sh exit {proc.returncode}):\n{log}",
                "env_seconds": seconds}
    return {"env_seconds": seconds, "env_log": log}


def _grid_dict(grid) -> dict:
    sys.path.insert(0, HERE)
    from surface_grid import MU, RHO, surface_grid  # noqa: PLC0415
    if grid is None:
        grid = surface_grid()
    if isinstance(grid, dict):
        g = dict(grid)
    else:
        tsr, pitch, rpm = grid
        g = {"tsr": tsr, "pitch": pitch, "rotor_speed_rpm": rpm}
    g["tsr"] = np.asarray(g["tsr"], float).tolist()
    g["pitch"] = np.asarray(g["pitch"], float).tolist()
    g["rotor_speed_rpm"] = float(g["rotor_speed_rpm"])
    g.setdefault("rho", RHO)
    g.setdefault("mu", MU)
    g.setdefault("airfoil_spline", os.environ.get("CALIB_BENCH_CCBLADE_SPLINE", "ccairfoil"))
    return g


def run(grid=None, rotor: str | None = None, repeats: int | None = None) -> dict:
    """CCBlade's surface and timing.

    Parameters
    ----------
    grid : tuple ``(tsr, pitch_deg, rotor_speed_rpm)`` or dict, optional
        Default :func:`surface_grid.surface_grid`. A dict may also set ``rho``, ``mu``,
        ``tilt_deg``, ``yaw_deg``, ``shear_exp``, ``n_sector``, ``tiploss``, ... (see
        ``ccblade_runner.py``).

    Returns
    -------
    dict
        ``ccblade_surface_seconds`` (best of the repeats, evaluation only), ``n_points``,
        ``cp``, ``ct`` (arrays ``(n_tsr, n_pitch)``, NaN where not converged),
        ``converged`` (bool array), ``tsr``, ``pitch``, ``rotor_speed_rpm``,
        ``ccblade_points_per_second``, ``ccblade_cp_max`` (+ its λ, β), versions,
        ``env_seconds`` (set-up / check of ``.bench-venv``), ``env_size_mb``; or
        ``{"error": message}``.
    """
    rotor = rotor or os.environ.get("CALIB_BENCH_ROTOR", "nrel5mw")
    repeats = int(repeats or os.environ.get("CALIB_BENCH_CCBLADE_REPEATS", 3))
    out: dict = {}
    try:
        env = ensure_env()
        out.update({k: v for k, v in env.items() if k != "env_log"})
        if "error" in env:
            return out
        out["env_size_mb"] = round(_dir_size_mb(VENV), 1)

        os.makedirs(OUT_DIR, exist_ok=True)
        rotor_json = os.path.join(OUT_DIR, f"rotor_{rotor}.json")
        grid_json = os.path.join(OUT_DIR, "grid.json")
        result_json = os.path.join(OUT_DIR, f"ccblade_surface_{rotor}.json")
        try:
            from export_rotor import export_rotor  # noqa: PLC0415  (HERE is on sys.path)
        except ImportError:
            sys.path.insert(0, HERE)
            from export_rotor import export_rotor  # noqa: PLC0415
        try:
            export_rotor(rotor, rotor_json)
        except Exception as exc:  # noqa: BLE001
            out["error"] = f"could not export rotor {rotor!r} for CCBlade: {type(exc).__name__}: {exc}"
            return out
        with open(grid_json, "w") as fh:
            json.dump(_grid_dict(grid), fh)
        if os.path.exists(result_json):
            os.remove(result_json)

        py = os.path.join(VENV, "bin", "python")
        cmd = [py, os.path.join(HERE, "ccblade_runner.py"), rotor_json, result_json,
               "--grid", grid_json, "--repeats", str(repeats)]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run(cmd, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            out["error"] = f"CCBlade surface run exceeded {RUN_TIMEOUT_S} s"
            return out
        out["ccblade_wall_seconds"] = time.perf_counter() - t0
        if proc.returncode != 0 or not os.path.exists(result_json):
            out["error"] = f"CCBlade run failed (exit {proc.returncode}):\n{_tail(proc.stderr + proc.stdout)}"
            return out
        with open(result_json) as fh:
            res = json.load(fh)
    except Exception as exc:  # noqa: BLE001  (never crash the benchmark runner)
        out["error"] = f"CCBlade benchmark failed: {type(exc).__name__}: {exc}"
        return out

    cp = np.array(res["cp"], dtype=float)
    ct = np.array(res["ct"], dtype=float)
    conv = np.array(res["converged"], dtype=bool)
    cp[~conv] = np.nan
    ct[~conv] = np.nan
    tsr = np.array(res["tsr"])
    pitch = np.array(res["pitch"])
    i, j = np.unravel_index(np.nanargmax(cp), cp.shape) if np.isfinite(cp).any() else (0, 0)
    out.update({
        "ccblade_surface_seconds": float(res["seconds"]),
        "ccblade_seconds_all": res["seconds_all"],
        "ccblade_repeats": res["repeats"],
        "n_points": int(res["n_points"]),
        "ccblade_points_per_second": res["n_points"] / res["seconds"],
        "cp": cp,
        "ct": ct,
        "converged": conv,
        "tsr": tsr,
        "pitch": pitch,
        "rotor_speed_rpm": res["rotor_speed_rpm"],
        "rotor_radius": res["rotor_radius"],
        "ccblade_n_not_converged": int(res["n_not_converged"]),
        "ccblade_cp_max": float(cp[i, j]),
        "ccblade_cp_max_tsr": float(tsr[i]),
        "ccblade_cp_max_pitch": float(pitch[j]),
        "ccblade_setup_seconds": res["setup_seconds"],
        "ccblade_version": f"wisdem {res['wisdem_version']} (numpy {res['numpy_version']}, "
                           f"scipy {res['scipy_version']}, python {res['python']})",
        "ccblade_settings": res["settings"],
        "ccblade_result_file": os.path.relpath(result_json, ROOT),
    })
    if res["settings"].get("airfoil_spline", "ccairfoil") == "ccairfoil":
        out.update(native_with_ccairfoil_smoothing(rotor, res, cp, conv))
        out.update(iea34_table_points())
    return out


def iea34_table_points() -> dict:
    """CCBlade 4.2.9 and the native BEM at the operating points of the IEA 3.4-MW CCBlade table.

    Returns |relative differences| in percent: ``iea34_ccblade_vs_table_*`` (CCBlade run here
    against the published table) and ``iea34_native_vs_ccblade_*`` (native, with CCAirfoil's
    smoothing and the validation test's set-up, against CCBlade run here), each as median and
    max below / above rated power, for power and thrust; or ``{"iea34_error": message}``.
    """
    try:
        from export_rotor import export_rotor  # noqa: PLC0415  (HERE is on sys.path)

        from calib.bem import BemSettings, SectionPolars, solve_bem  # noqa: PLC0415
        from calib.rotor.library import load_rotor, reference_path  # noqa: PLC0415
        from calib.types import OperatingConditions  # noqa: PLC0415

        table = np.loadtxt(reference_path("IEA-3.4-130-RWT_performance_ccblade.dat"))
        rotor = load_rotor("iea3.4")
        rotor_json = os.path.join(OUT_DIR, "rotor_iea3.4.json")
        points_json = os.path.join(OUT_DIR, "iea34_table_points.json")
        result_json = os.path.join(OUT_DIR, "ccblade_iea34_table_points.json")
        export_rotor("iea3.4", rotor_json)
        with open(points_json, "w") as fh:
            json.dump({"wind_speed": table[:, 0].tolist(), "rotor_speed_rpm": table[:, 1].tolist(),
                       "pitch_deg": table[:, 2].tolist(), "tilt_deg": float(rotor.tilt_deg), "shear_exp": 0.2,
                       "n_sector": 4}, fh)
        proc = subprocess.run([os.path.join(VENV, "bin", "python"), os.path.join(HERE, "ccblade_runner.py"),
                               rotor_json, result_json, "--points", points_json], capture_output=True, text=True,
                              timeout=RUN_TIMEOUT_S)
        if proc.returncode != 0:
            return {"iea34_error": f"CCBlade run failed (exit {proc.returncode}):\n{_tail(proc.stderr + proc.stdout)}"}
        with open(result_json) as fh:
            cc = json.load(fh)
        nat = solve_bem(rotor, OperatingConditions(table[:, 0], table[:, 1], table[:, 2]),
                        BemSettings(shear_exponent=0.2, n_sectors=4),
                        polars=SectionPolars.from_rotor(rotor, smoothing=CCAIRFOIL_SMOOTHING))
    except Exception as exc:  # noqa: BLE001  (never crash the benchmark runner)
        return {"iea34_error": f"{type(exc).__name__}: {exc}"}
    below = table[:, 4] < 0.999 * table[:, 4].max()
    ok = np.asarray(cc["converged"], bool) & nat.ok
    out = {"iea34_points_compared": int(ok.sum()), "iea34_native_multiple_root_points": int(nat.multiple_roots.sum())}
    pairs = {"ccblade_vs_table": ((np.asarray(cc["P"]), table[:, 4]), (np.asarray(cc["T"]), table[:, 5])),
             "native_vs_ccblade": ((nat.power, np.asarray(cc["P"])), (nat.thrust, np.asarray(cc["T"])))}
    for name, ((p_a, p_b), (t_a, t_b)) in pairs.items():
        for q, a, b in (("power", p_a, p_b), ("thrust", t_a, t_b)):
            d = 100 * np.abs(a / b - 1)
            out[f"iea34_{name}_{q}_median_pct"] = float(np.median(d[ok]))
            out[f"iea34_{name}_{q}_max_below_rated_pct"] = float(d[ok & below].max())
            out[f"iea34_{name}_{q}_max_above_rated_pct"] = float(d[ok & ~below].max())
    return out


def native_with_ccairfoil_smoothing(rotor_name: str, res: dict, cp_cc: np.ndarray, conv: np.ndarray) -> dict:
    """The native surface on CCBlade's grid with CCAirfoil's polar smoothing, against CCBlade.

    Same set-up as CCBlade's run (axisymmetric, one sector); returns ``smoothed_native_max_abs_dcp``
    (and its λ, β) and ``smoothed_native_median_abs_dcp`` over the points converged in both, or
    ``{"smoothed_native_error": message}``.
    """
    try:
        from surface_grid import surface_points  # noqa: PLC0415  (HERE is on sys.path)

        from calib.bem import BemSettings, SectionPolars, solve_bem  # noqa: PLC0415
        from calib.rotor.library import load_rotor  # noqa: PLC0415
        from calib.types import OperatingConditions  # noqa: PLC0415

        rotor = load_rotor(rotor_name)
        tsr, pitch = np.asarray(res["tsr"], float), np.asarray(res["pitch"], float)
        v, om, beta = surface_points(tsr, pitch, res["rotor_speed_rpm"], rotor.rotor_radius)
        settings = res["settings"]
        cond = OperatingConditions(v, om, beta, settings["rho"])
        nat = solve_bem(rotor, cond, BemSettings(use_tilt=False, n_sectors=1),
                        polars=SectionPolars.from_rotor(rotor, smoothing=CCAIRFOIL_SMOOTHING))
    except Exception as exc:  # noqa: BLE001  (never crash the benchmark runner)
        return {"smoothed_native_error": f"{type(exc).__name__}: {exc}"}
    cp = nat.cp.reshape(cp_cc.shape)
    both = conv & np.isfinite(cp) & np.isfinite(cp_cc)
    if not both.any():
        return {"smoothed_native_error": "no point converged in both"}
    d = np.where(both, np.abs(cp - cp_cc), -np.inf)
    i, j = np.unravel_index(np.argmax(d), d.shape)
    return {"smoothed_native_max_abs_dcp": float(d[i, j]), "smoothed_native_max_abs_dcp_tsr": float(tsr[i]),
            "smoothed_native_max_abs_dcp_pitch": float(pitch[j]),
            "smoothed_native_median_abs_dcp": float(np.median(np.abs(cp - cp_cc)[both])),
            "smoothed_native_points_compared": int(both.sum())}


if __name__ == "__main__":
    r = run()
    if "error" in r:
        print(r["error"])
        sys.exit(1)
    print({k: v for k, v in r.items() if not isinstance(v, np.ndarray)})
