"""Compute a C_P(λ, β) surface with WISDEM's CCBlade and time it.

Runs INSIDE the separate benchmark environment (``.bench-venv``, made by
``ccblade_env.sh``), never in the project's environment; it needs only numpy, scipy
and the ``wisdem`` package files (imported without running ``wisdem/__init__.py``,
which would pull in OpenMDAO and the rest of WISDEM).

Usage::

    .bench-venv/bin/python benchmarks/ccblade_runner.py ROTOR_JSON OUT_JSON \
        [--grid GRID_JSON] [--repeats N]
    .bench-venv/bin/python benchmarks/ccblade_runner.py ROTOR_JSON OUT_JSON --points POINTS_JSON
    .bench-venv/bin/python benchmarks/ccblade_runner.py --check

``ROTOR_JSON`` is written by ``export_rotor.py``. ``GRID_JSON`` (optional; default:
``surface_grid.surface_grid()``) holds ``tsr``, ``pitch``, ``rotor_speed_rpm`` and
optionally ``rho``, ``mu``, ``tilt_deg``, ``yaw_deg``, ``shear_exp``, ``n_sector``,
``tiploss``, ``hubloss``, ``wakerotation``, ``usecd``, ``end_stations``
(``"drop"``, default, or ``"ccblade"``: see :func:`build_rotor`) and ``airfoil_spline``
(``"ccairfoil"``, default, or ``"linear"``: see :func:`build_airfoil`).

Settings (same as the native surface): Prandtl tip and hub loss, wake rotation, drag
in the induction, the rotor's precone, precurve and presweep; tilt = yaw = shear = 0,
hence one azimuthal sector (CCBlade itself uses nSector = 1 when all three are 0).
The airfoils are the raw polar tables (CCAirfoil fits its smoothing bivariate spline
to them, as CCBlade always does); a table that does not reach ±180 deg is first extended with WISDEM's
Viterna extrapolation.

``POINTS_JSON`` (instead of a grid) holds lists ``wind_speed``, ``rotor_speed_rpm``,
``pitch_deg`` and the same optional settings; the output then has per-point lists ``P``,
``T``, ``Q``, ``Mb`` (CCBlade's power [W], thrust [N], torque [N m], flap moment [N m]) and
``converged``.

Output JSON (grid): ``cp``, ``ct``, ``cq`` and ``converged`` as nested lists of shape
(n_tsr, n_pitch), ``seconds`` (best of the repeats), ``seconds_all``, ``n_points``,
``setup_seconds`` and the versions. Only ``rotor.evaluate`` over the whole grid is
inside the timer (``time.perf_counter``); building CCAirfoil/CCBlade is not.
A point counts as not converged when CCBlade's bracketing or Brent solve failed at
any section (it then warns, or prints "NaNs at" and zeroes the section) or when its
result is not finite.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import math
import os
import platform
import sys
import time
import types
import warnings

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def import_ccblade():
    """Return the ``wisdem.ccblade.ccblade`` module.

    WISDEM's top-level ``__init__`` imports its whole glue code (OpenMDAO, ...). The
    minimal environment has only the package files plus numpy/scipy, so when that
    import fails we register a bare ``wisdem`` namespace (same ``__path__``) and import
    the CCBlade submodule from it: the same files, nothing else executed.
    """
    try:
        import wisdem.ccblade.ccblade as ccb  # noqa: PLC0415  (full WISDEM install)
        return ccb
    except ImportError:
        for name in [m for m in sys.modules if m == "wisdem" or m.startswith("wisdem.")]:
            del sys.modules[name]
    spec = importlib.util.find_spec("wisdem")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("the 'wisdem' package is not installed in this environment "
                          f"({sys.executable}); run benchmarks/ccblade_env.sh")
    pkg = types.ModuleType("wisdem")
    pkg.__path__ = list(spec.submodule_search_locations)
    pkg.__file__ = spec.origin
    sys.modules["wisdem"] = pkg
    import wisdem.ccblade.ccblade as ccb  # noqa: PLC0415
    return ccb


def wisdem_version() -> str:
    try:
        from importlib.metadata import version
        return version("wisdem")
    except Exception:  # noqa: BLE001
        return "unknown"


def _full_circle(alpha, cl, cd):
    """Extend a table to ±180 deg with WISDEM's Viterna method when it does not reach it."""
    alpha = np.asarray(alpha, float)
    if alpha[0] <= -179.5 and alpha[-1] >= 179.5:
        return alpha, np.asarray(cl, float), np.asarray(cd, float)
    import wisdem.ccblade.Polar as wpolar  # noqa: PLC0415
    cdmax = max(1.3, float(np.max(cd)))
    p = wpolar.Polar(0.0, alpha, cl, cd, np.zeros_like(alpha)).extrapolate(cdmax)
    return np.asarray(p.alpha, float), np.asarray(p.cl, float), np.asarray(p.cd, float)


def build_airfoil(ccb, airfoil: dict, spline: str = "ccairfoil"):
    """CCAirfoil from the raw tables of one airfoil (several tables: 2-D in α × Re).

    ``spline="ccairfoil"`` (default) keeps CCAirfoil's own fit: a cubic smoothing
    spline (s = 0.01 on C_L, 0.001 on C_D), which visibly rounds the tables near stall.
    ``spline="linear"`` replaces it by interpolation through the table points (a
    diagnostic: it isolates the polar-smoothing part of a difference to another code).
    """
    tables = [_full_circle(t["alpha_deg"], t["cl"], t["cd"]) for t in airfoil["tables"]]
    res = [t.get("Re") for t in airfoil["tables"]]
    name = airfoil.get("name", "af")
    if len(tables) == 1:
        alpha, cl, cd = tables[0]
        af = ccb.CCAirfoil(alpha, [], cl, cd, AFName=name)
        re_axis, cl2, cd2 = np.array([1e1, 1e15]), np.c_[cl, cl], np.c_[cd, cd]
    else:
        order = np.argsort(res)
        alpha = np.unique(np.concatenate([tables[k][0] for k in order]))
        cl2 = np.column_stack([np.interp(alpha, tables[k][0], tables[k][1]) for k in order])
        cd2 = np.column_stack([np.interp(alpha, tables[k][0], tables[k][2]) for k in order])
        re_axis = np.asarray(res, float)[order]
        af = ccb.CCAirfoil(alpha, re_axis, cl2, cd2, AFName=name)
    if spline == "linear":
        from scipy.interpolate import RectBivariateSpline  # noqa: PLC0415
        a = np.deg2rad(alpha)
        af.cl_spline = RectBivariateSpline(a, re_axis, cl2, kx=1, ky=1, s=0)
        af.cd_spline = RectBivariateSpline(a, re_axis, cd2, kx=1, ky=1, s=0)
    elif spline != "ccairfoil":
        raise ValueError(f"airfoil_spline must be 'ccairfoil' or 'linear', got {spline!r}")
    return af


def load_grid(path: str | None) -> dict:
    if path:
        with open(path) as fh:
            grid = json.load(fh)
    else:
        sys.path.insert(0, HERE)
        from surface_grid import MU, RHO, surface_grid  # noqa: PLC0415
        tsr, pitch, rpm = surface_grid()
        grid = {"tsr": tsr.tolist(), "pitch": pitch.tolist(), "rotor_speed_rpm": rpm,
                "rho": RHO, "mu": MU}
    grid.setdefault("rho", 1.225)
    grid.setdefault("mu", 1.81206e-5)
    return grid


def build_rotor(ccb, rotor: dict, grid: dict):
    spline = grid.get("airfoil_spline", "ccairfoil")
    afs = [build_airfoil(ccb, a, spline) for a in rotor["airfoils"]]
    r = np.asarray(rotor["r"], float)
    n = r.size
    hub, tip = float(rotor["hub_radius"]), float(rotor["tip_radius"])
    precurve = np.asarray(rotor.get("precurve") or np.zeros(n), float)
    presweep = np.asarray(rotor.get("presweep") or np.zeros(n), float)
    # Stations lying on the hub or tip radius: calib gives them zero load, which is what
    # CCBlade does with Rhub / Rtip themselves (it integrates from Rhub to Rtip with zero
    # load there), so they are dropped ("drop", default). With "ccblade" they are kept and
    # CCBlade moves them inward (to 1 % / 99 % of the span) and solves BEM there.
    keep = np.ones(n, bool)
    if grid.get("end_stations", "drop") == "drop":
        tol = 1e-9 * tip
        keep = (r > hub + tol) & (r < tip - tol)
    af = [afs[int(k)] for k, kept in zip(rotor["airfoil_id"], keep) if kept]
    settings = dict(
        B=int(rotor["n_blades"]),
        rho=float(grid["rho"]),
        mu=float(grid["mu"]),
        precone=float(rotor.get("precone_deg", 0.0)),
        tilt=float(grid.get("tilt_deg", 0.0)),
        yaw=float(grid.get("yaw_deg", 0.0)),
        shearExp=float(grid.get("shear_exp", 0.0)),
        hubHt=float(rotor.get("hub_height") or 90.0),
        nSector=int(grid.get("n_sector", 1)),
        precurveTip=float(rotor.get("precurve_tip", 0.0)),
        presweepTip=float(rotor.get("presweep_tip", 0.0)),
        tiploss=bool(grid.get("tiploss", True)),
        hubloss=bool(grid.get("hubloss", True)),
        wakerotation=bool(grid.get("wakerotation", True)),
        usecd=bool(grid.get("usecd", True)),
        iterRe=1,
        derivatives=False,
    )
    model = ccb.CCBlade(
        r[keep], np.asarray(rotor["chord"], float)[keep],
        np.asarray(rotor["twist_deg"], float)[keep], af, hub, tip,
        precurve=precurve[keep], presweep=presweep[keep], **settings)
    settings["end_stations"] = grid.get("end_stations", "drop")
    settings["airfoil_spline"] = spline
    return model, settings


class _StatusRecorder:
    """Wraps ``CCBlade.distributedAeroLoads`` to flag, per call, a failed section solve.

    CCBlade.evaluate calls ``self.distributedAeroLoads`` once per point and sector, so an
    instance attribute intercepts it; the cost is a Python call plus a warnings/stdout
    context per call (microseconds, against milliseconds for the call itself).
    """

    def __init__(self, model):
        self.inner = model.distributedAeroLoads
        self.failed: list[bool] = []
        model.distributedAeroLoads = self

    def __call__(self, *args, **kwargs):
        out = io.StringIO()
        with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out):
            warnings.simplefilter("always")
            result = self.inner(*args, **kwargs)
        self.failed.append(bool(caught) or "NaNs at" in out.getvalue())
        return result


def run(rotor: dict, grid: dict, repeats: int = 1) -> dict:
    t0 = time.perf_counter()
    ccb = import_ccblade()
    model, settings = build_rotor(ccb, rotor, grid)
    setup = time.perf_counter() - t0

    tsr = np.asarray(grid["tsr"], float)
    pitch = np.asarray(grid["pitch"], float)
    rpm = float(grid["rotor_speed_rpm"])
    radius = float(rotor.get("rotor_radius")
                   or rotor["tip_radius"] * math.cos(math.radians(rotor.get("precone_deg", 0.0))))
    lam, beta = np.meshgrid(tsr, pitch, indexing="ij")
    wind = (rpm * math.pi / 30.0) * radius / lam
    uinf, omega, pit = wind.ravel(), np.full(lam.size, rpm), beta.ravel()

    recorder = _StatusRecorder(model)
    times = []
    for _ in range(max(1, int(repeats))):
        recorder.failed = []
        t0 = time.perf_counter()
        out, _ = model.evaluate(uinf, omega, pit, coefficients=False)
        times.append(time.perf_counter() - t0)

    nsec = model.nSector
    failed = np.asarray(recorder.failed, bool).reshape(lam.size, nsec).any(axis=1)
    power, thrust, torque = out["P"], out["T"], out["Q"]
    area = math.pi * radius ** 2
    q = 0.5 * settings["rho"] * uinf ** 2
    cp = power / (q * uinf * area)
    ct = thrust / (q * area)
    cq = torque / (q * area * radius)
    converged = ~failed & np.isfinite(cp) & np.isfinite(ct)
    shape = lam.shape

    def grid_list(a):
        a = np.where(np.isfinite(a), a, np.nan).reshape(shape)
        return [[None if math.isnan(v) else float(v) for v in row] for row in a]

    return {
        "code": "CCBlade (WISDEM)",
        "wisdem_version": wisdem_version(),
        "numpy_version": np.__version__,
        "scipy_version": __import__("scipy").__version__,
        "python": platform.python_version(),
        "rotor": rotor.get("name", "?"),
        "tsr": tsr.tolist(),
        "pitch": pitch.tolist(),
        "rotor_speed_rpm": rpm,
        "rotor_radius": radius,
        "n_points": int(lam.size),
        "n_sector": int(nsec),
        "repeats": len(times),
        "seconds": min(times),
        "seconds_all": times,
        "setup_seconds": setup,
        "settings": {k: v for k, v in settings.items()},
        "r_used": model.r.tolist(),  # the stations CCBlade solved (see build_rotor)
        "cp": grid_list(cp),
        "ct": grid_list(ct),
        "cq": grid_list(cq),
        "converged": converged.reshape(shape).tolist(),
        "n_not_converged": int((~converged).sum()),
    }


def run_points(rotor: dict, spec: dict) -> dict:
    """CCBlade's loads at a list of operating points (``--points``)."""
    ccb = import_ccblade()
    spec = dict(spec)
    spec.setdefault("rho", 1.225)
    spec.setdefault("mu", 1.81206e-5)
    model, settings = build_rotor(ccb, rotor, spec)
    recorder = _StatusRecorder(model)
    wind = np.asarray(spec["wind_speed"], float)
    out, _ = model.evaluate(wind, np.asarray(spec["rotor_speed_rpm"], float), np.asarray(spec["pitch_deg"], float),
                            coefficients=False)
    failed = np.asarray(recorder.failed, bool).reshape(wind.size, model.nSector).any(axis=1)
    res = {k: np.asarray(out[k], float) for k in ("P", "T", "Q", "Mb")}
    converged = ~failed & np.all([np.isfinite(v) for v in res.values()], axis=0)
    return {"code": "CCBlade (WISDEM)", "wisdem_version": wisdem_version(), "settings": settings,
            **{k: [float(x) for x in v] for k, v in res.items()}, "converged": converged.tolist()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("rotor", nargs="?", help="rotor JSON (export_rotor.py)")
    ap.add_argument("out", nargs="?", help="result JSON to write")
    ap.add_argument("--grid", help="grid JSON (default: surface_grid.surface_grid())")
    ap.add_argument("--repeats", type=int, default=int(os.environ.get("CALIB_BENCH_CCBLADE_REPEATS", 1)),
                    help="time this many evaluations of the surface, keep the best (default 1)")
    ap.add_argument("--points", help="points JSON: loads at these operating points instead of a surface")
    ap.add_argument("--check", action="store_true", help="only check that CCBlade imports")
    args = ap.parse_args(argv)
    if args.check:
        ccb = import_ccblade()
        print(f"wisdem {wisdem_version()} CCBlade OK ({ccb.__file__}); numpy {np.__version__}")
        return 0
    if not (args.rotor and args.out):
        ap.error("ROTOR_JSON and OUT_JSON are required (or --check)")
    with open(args.rotor) as fh:
        rotor = json.load(fh)
    if args.points:
        with open(args.points) as fh:
            result = run_points(rotor, json.load(fh))
        with open(args.out, "w") as fh:
            json.dump(result, fh)
        print(f"CCBlade {len(result['P'])} points, {len(result['P']) - sum(result['converged'])} not converged")
        return 0
    result = run(rotor, load_grid(args.grid), args.repeats)
    with open(args.out, "w") as fh:
        json.dump(result, fh)
    cp = np.array(result["cp"], dtype=float)
    i, j = np.unravel_index(np.nanargmax(cp), cp.shape)
    print(f"CCBlade {result['n_points']} points: best {result['seconds']:.3f} s of {result['repeats']} "
          f"({result['n_points'] / result['seconds']:.0f} points/s); "
          f"C_P max {cp[i, j]:.4f} at λ = {result['tsr'][i]:.2f}, β = {result['pitch'][j]:.2f} deg; "
          f"{result['n_not_converged']} points not converged")
    return 0


if __name__ == "__main__":
    sys.exit(main())
