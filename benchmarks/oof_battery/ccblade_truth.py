"""Noise-free truth of every data set of one set-up, computed by WISDEM's CCBlade.

Runs INSIDE the CCBlade environment (``.bench-venv``, made by ``benchmarks/ccblade_env.sh``)::

    .bench-venv/bin/python benchmarks/oof_battery/ccblade_truth.py ROTOR_JSON SPEC_JSON OUT_JSON

``ROTOR_JSON`` is written by ``benchmarks/export_rotor.py`` (for the set-up's precone).
``SPEC_JSON`` holds the operating points (``wind_speed``, ``rotor_speed_rpm``, ``pitch_deg``),
the set-up (``tilt_deg``, ``shear_exp``, ``n_sector``; optional ``rho``, ``mu``) and
``data_sets``: a list of ``{"name", "hidden"}`` with ``hidden`` one of ``none``,
``correction3D``, ``reynolds``, ``uniform``, ``erosion``, ``blockage`` (forms in
``hidden_effects.py``).

The CCBlade model is built by ``ccblade_runner.build_rotor`` exactly as ``bench_ccblade``
builds it (CCAirfoil's smoothing spline, Prandtl tip and hub loss, wake rotation, drag in
the induction, end stations dropped); a failed section solve is detected by
``ccblade_runner._StatusRecorder``. Output JSON: ``data_sets`` → name → ``P`` [W], ``T``
[N], ``Q`` [N m], ``Mb`` [N m] (CCBlade's flap moment of one blade about the rotor centre),
``converged`` (per point), ``details`` (what the hidden effect did: Reynolds-number ratios
seen, blockage speed ratios and iterations, ...); plus ``wisdem_version``, ``settings`` and
the effect ``parameters``.
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))     # benchmarks/: ccblade_runner, oof_battery

import ccblade_runner  # noqa: E402
from oof_battery import hidden_effects as hx  # noqa: E402

#: Relative change of the blockage speed below which its iteration has settled [-].
BLOCKAGE_TOLERANCE = 1e-10
BLOCKAGE_MAX_ITERATIONS = 60


def _evaluate(model, wind, rpm, pitch) -> dict:
    """CCBlade's loads at the points, with a per-point flag of a failed section solve."""
    recorder = ccblade_runner._StatusRecorder(model)
    try:
        out, _ = model.evaluate(np.asarray(wind, float), np.asarray(rpm, float), np.asarray(pitch, float),
                                coefficients=False)
    finally:
        model.distributedAeroLoads = recorder.inner
    failed = np.asarray(recorder.failed, bool).reshape(len(wind), model.nSector).any(axis=1)
    res = {k: np.asarray(out[k], float) for k in ("P", "T", "Q", "Mb")}
    res["converged"] = ~failed & np.all([np.isfinite(v) for v in res.values()], axis=0)
    return res


def _kept(rotor: dict) -> np.ndarray:
    """Indices of the stations ``build_rotor`` keeps (those strictly between hub and tip)."""
    r = np.asarray(rotor["r"], float)
    tol = 1e-9 * float(rotor["tip_radius"])
    return np.flatnonzero((r > float(rotor["hub_radius"]) + tol) & (r < float(rotor["tip_radius"]) - tol))


def _reynolds_model(ccb, rotor: dict, spec: dict):
    """CCBlade with every lifting section's airfoil seen at its own Reynolds number."""
    model, settings = ccblade_runner.build_rotor(ccb, rotor, spec)
    keep = _kept(rotor)
    if len(keep) != len(model.af):
        raise RuntimeError(f"expected {len(keep)} sections, CCBlade has {len(model.af)}")
    nu = settings["mu"] / settings["rho"]
    r, chord = np.asarray(rotor["r"], float)[keep], np.asarray(rotor["chord"], float)[keep]
    re_ref = hx.reference_reynolds(r, chord, float(rotor["tip_radius"]), nu)
    wrapped = []
    for j, k in enumerate(keep):
        table = rotor["airfoils"][int(rotor["airfoil_id"][k])]["tables"][0]
        if len(rotor["airfoils"][int(rotor["airfoil_id"][k])]["tables"]) != 1:
            raise RuntimeError("the Reynolds-number data set needs one table per airfoil")
        if hx.is_lifting(table["cl"]):
            model.af[j] = hx.ReynoldsAirfoil(model.af[j], re_ref[j], hx.minimum_drag(table["alpha_deg"], table["cd"]),
                                             hx.stall_angle(table["alpha_deg"], table["cl"]))
            wrapped.append(j)
    model.iterRe = 2          # Re from the induced velocity of the first pass (CCBlade's "high accuracy")
    return model, {"re_ref": re_ref.tolist(), "r": r.tolist(), "wrapped_sections": wrapped}


def _reynolds_at_solution(model, wind, rpm, pitch, info) -> dict:
    """Re/Re_ref at the converged sections (azimuth 0) over all points: percentiles."""
    ratios = []
    for v, om, b in zip(wind, rpm, pitch):
        loads, _ = model.distributedAeroLoads(float(v), float(om), float(b), 0.0)
        re = np.asarray(loads["Re"], float)
        ratios.append(re[info["wrapped_sections"]] / np.asarray(info["re_ref"])[info["wrapped_sections"]])
    ratios = np.concatenate(ratios)
    q = np.percentile(ratios, [0, 10, 50, 90, 100])
    return {"re_over_re_ref_percentiles_0_10_50_90_100": q.tolist()}


def _blockage(model, settings, spec, wind, rpm, pitch) -> tuple[dict, dict]:
    """Loads at the equivalent free-stream speed of the tunnel speed ``wind``, iterated with the thrust."""
    area = math.pi * float(model.rotorR) ** 2
    rho = settings["rho"]
    u_t = np.asarray(wind, float)
    u_f = u_t.copy()
    for it in range(1, BLOCKAGE_MAX_ITERATIONS + 1):
        res = _evaluate(model, u_f, rpm, pitch)
        ct = res["T"] / (0.5 * rho * area * u_t ** 2)
        new = u_t * np.array([hx.blockage_speed_ratio(c, hx.BLOCKAGE_AREA_RATIO) for c in ct])
        change = float(np.max(np.abs(new - u_f) / u_t))
        u_f = new
        if change < BLOCKAGE_TOLERANCE:
            break
    else:
        raise RuntimeError(f"blockage iteration did not settle in {BLOCKAGE_MAX_ITERATIONS} iterations "
                           f"(last change {change:.3g})")
    res = _evaluate(model, u_f, rpm, pitch)
    ratio = u_f / u_t
    return res, {"iterations": it, "speed_ratio_min": float(ratio.min()), "speed_ratio_max": float(ratio.max()),
                 "ct_tunnel_max": float(np.max(res["T"] / (0.5 * rho * area * u_t ** 2))),
                 "area_ratio": hx.BLOCKAGE_AREA_RATIO, "swept_area_m2": area}


def truth(rotor: dict, spec: dict, hidden: str) -> dict:
    """Loads of one data set: ``hidden`` names the effect form (module docstring)."""
    ccb = ccblade_runner.import_ccblade()
    wind, rpm, pitch = spec["wind_speed"], spec["rotor_speed_rpm"], spec["pitch_deg"]
    details: dict = {}
    if hidden in ("none", "blockage"):
        model, settings = ccblade_runner.build_rotor(ccb, rotor, spec)
        if hidden == "none":
            res = _evaluate(model, wind, rpm, pitch)
        else:
            res, details = _blockage(model, settings, spec, wind, rpm, pitch)
    elif hidden == "reynolds":
        model, info = _reynolds_model(ccb, rotor, spec)
        res = _evaluate(model, wind, rpm, pitch)
        details = {"re_ref_min": min(info["re_ref"]), "re_ref_max": max(info["re_ref"]),
                   **_reynolds_at_solution(model, wind, rpm, pitch, info)}
    else:
        changed = {"correction3D": hx.correction3d_rotor, "uniform": hx.uniform_rotor,
                   "erosion": hx.erosion_rotor}[hidden](rotor)
        model, settings = ccblade_runner.build_rotor(ccb, changed, spec)
        res = _evaluate(model, wind, rpm, pitch)
    return {**{k: [float(x) for x in res[k]] for k in ("P", "T", "Q", "Mb")},
            "converged": [bool(x) for x in res["converged"]], "details": details}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3:
        sys.exit("usage: ccblade_truth.py ROTOR_JSON SPEC_JSON OUT_JSON")
    with open(argv[0]) as fh:
        rotor = json.load(fh)
    with open(argv[1]) as fh:
        spec = json.load(fh)
    spec.setdefault("rho", 1.225)
    spec.setdefault("mu", 1.81206e-5)
    ccb = ccblade_runner.import_ccblade()
    _, settings = ccblade_runner.build_rotor(ccb, rotor, spec)
    out = {"code": "CCBlade (WISDEM)", "wisdem_version": ccblade_runner.wisdem_version(),
           "numpy_version": np.__version__, "settings": settings, "parameters": hx.PARAMETERS, "data_sets": {}}
    for ds in spec["data_sets"]:
        res = truth(rotor, spec, ds["hidden"])
        out["data_sets"][ds["name"]] = res
        n_bad = len(res["converged"]) - sum(res["converged"])
        print(f"[oof truth] {ds['name']} ({ds['hidden']}): {len(res['P'])} points, {n_bad} not converged"
              + (f"; {res['details']}" if res["details"] else ""), flush=True)
    with open(argv[2], "w") as fh:
        json.dump(out, fh)
    return 0


if __name__ == "__main__":
    sys.exit(main())
