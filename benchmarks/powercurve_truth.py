"""Truth of the power-curve validation (issue 41 item 4), computed by WISDEM's CCBlade.

Runs INSIDE the CCBlade environment (``.bench-venv``, made by ``benchmarks/ccblade_env.sh``)::

    .bench-venv/bin/python benchmarks/powercurve_truth.py ROTOR_JSON SPEC_JSON OUT_JSON

``ROTOR_JSON`` from ``benchmarks/export_rotor.py``; ``SPEC_JSON`` holds the calibration's operating
points (``wind_speed``, ``rotor_speed_rpm``, ``pitch_deg``), the power-curve bins ``bins`` [m/s],
the variable-speed ``schedule`` (``rated_power`` [W], ``min_rotor_speed``, ``max_rotor_speed``
[rpm], ``design_tsr``, ``fine_pitch`` [deg], ``rotor_radius`` [m]) and ``data_sets``: a list of
``{"name", "hidden", "pitch_offset"}`` with ``hidden`` a form of ``oof_battery/hidden_effects.py``
(``none``, ``correction3D``, ``reynolds``, ``uniform``, ``erosion``) and ``pitch_offset`` [deg]
added to every commanded pitch (a blade-pitch calibration error of the truth turbine).

Per data set: CCBlade's ``P``, ``T``, ``Q``, ``Mb`` at the operating points (as
``oof_battery/ccblade_truth.py``) and its power curve through the same schedule as calib's
:class:`calib.powercurve.schedule.VariableSpeed` with ``tsr_rule="optimal"``: λ* of maximum
C_P at fine pitch and maximum rotor speed on the same 13-point grid (±35 % of the design λ)
refined by the parabola through the best three; region 2 at Ω = λ* V / R clipped to the speed
limits, fine pitch; where that gives more than rated power, region 3 at the commanded pitch
where CCBlade's power equals rated (Brent's method on [fine pitch, 45°], relative tolerance
1e-8 on the pitch). Output ``curve``: ``power`` [W], ``rotor_speed`` [rpm], ``pitch`` [deg],
``region``, ``converged`` per bin and ``tsr_opt``.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, os.path.join(HERE, "oof_battery"))

import ccblade_runner  # noqa: E402
from oof_battery import ccblade_truth as ct  # noqa: E402
from oof_battery import hidden_effects as hx  # noqa: E402


def _model(ccb, rotor: dict, spec: dict, hidden: str):
    if hidden == "none":
        return ccblade_runner.build_rotor(ccb, rotor, spec)[0]
    if hidden == "reynolds":
        model, _ = ct._reynolds_model(ccb, rotor, spec)
        return model
    changed = {"correction3D": hx.correction3d_rotor, "uniform": hx.uniform_rotor,
               "erosion": hx.erosion_rotor}[hidden](rotor)
    return ccblade_runner.build_rotor(ccb, changed, spec)[0]


def _power(model, v, rpm, pitch):
    res = ct._evaluate(model, np.atleast_1d(v), np.atleast_1d(rpm), np.atleast_1d(pitch))
    return res["P"], res["converged"]


def scheduled_curve(model, s: dict, bins, offset: float) -> dict:
    """CCBlade's power curve through the variable-speed schedule (module notes)."""
    from scipy.optimize import brentq

    lam = s["design_tsr"] * np.linspace(0.65, 1.35, 13)
    omega = s["max_rotor_speed"] * np.pi / 30
    vl = omega * s["rotor_radius"] / lam
    P, ok = _power(model, vl, np.full(lam.size, s["max_rotor_speed"]), np.full(lam.size, s["fine_pitch"] + offset))
    cp = np.where(ok, P / vl ** 3, -np.inf)            # ∝ C_P at fixed ρ and R
    k = int(np.argmax(cp))
    tsr = float(lam[k])
    if 0 < k < lam.size - 1:
        x, y = lam[k - 1:k + 2], cp[k - 1:k + 2]
        a, b, _ = np.polyfit(x, y, 2)
        if a < 0:
            tsr = float(np.clip(-b / (2 * a), x[0], x[2]))
    v = np.asarray(bins, float)
    rpm = np.clip(tsr * v / s["rotor_radius"] * 30 / np.pi, s["min_rotor_speed"], s["max_rotor_speed"])
    pitch = np.full(v.size, float(s["fine_pitch"]))
    power, conv = _power(model, v, rpm, pitch + offset)
    region = np.full(v.size, 2)
    for i in np.flatnonzero(conv & (power > s["rated_power"])):
        def f(beta, i=i):
            p, c = _power(model, v[i], rpm[i], beta + offset)
            return p[0] - s["rated_power"] if c[0] else np.nan
        hi = 45.0
        if not f(hi) < 0:
            conv[i] = False
            continue
        pitch[i] = brentq(f, s["fine_pitch"], hi, xtol=1e-10, rtol=1e-10)
        p, c = _power(model, v[i], rpm[i], pitch[i] + offset)
        power[i], conv[i], region[i] = p[0], c[0], 3
    return {"power": power.tolist(), "rotor_speed": rpm.tolist(), "pitch": pitch.tolist(),
            "region": region.tolist(), "converged": [bool(c) for c in conv], "tsr_opt": tsr}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    rotor = json.loads(open(argv[0]).read())
    spec = json.loads(open(argv[1]).read())
    spec.setdefault("rho", 1.225)
    spec.setdefault("mu", 1.81206e-5)
    ccb = ccblade_runner.import_ccblade()
    out = {"wisdem_version": ccblade_runner.wisdem_version(), "data_sets": {}}
    for d in spec["data_sets"]:
        offset = float(d.get("pitch_offset", 0.0))
        pts = dict(spec, pitch_deg=[b + offset for b in spec["pitch_deg"]])
        loads = ct.truth(rotor, pts, d["hidden"])
        model = _model(ccb, rotor, spec, d["hidden"])
        curve = scheduled_curve(model, spec["schedule"], spec["bins"], offset)
        out["data_sets"][d["name"]] = {**loads, "curve": curve}
        print(f"{d['name']}: tsr_opt {curve['tsr_opt']:.4f}, {sum(curve['converged'])} of {len(spec['bins'])} bins",
              flush=True)
    with open(argv[2], "w") as fh:
        json.dump(out, fh)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
