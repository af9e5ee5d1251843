"""Battery data from the lifting line (``lifting_line.py``): the rigid set-up's points, noisy CSVs, config.

The out-of-family battery (``benchmarks/oof_battery/``) makes its data with CCBlade, another
BEM. This module makes the same kind of data with the steady lifting line, a vortex method:
the ``control`` data set (the rotor's own polars) measures what calib's diagnosis names for a
difference of *method* alone; the effect data sets change the polars the lifting line uses.

Operating points and channels: ``campaign.operating_points`` (63 points: λ sweep and pitch
sweeps at 9 and 6 rpm) and ``campaign.CHANNELS`` (``power``, ``thrust``, ``torque``,
``hub_flap_moment``), the ``rigid`` set-up (tilt 0, precone 0, no shear). 1 % Gaussian noise
(``campaign.noise_sigma``, ``campaign.noisy``), seeds :data:`SEED0` + k, CSVs written by calib's
``Measurements.write_csv`` as ``generate.write_csv`` does, and ``config_rigid.toml`` from
``generate.config_text("rigid")``. Layout (the battery's)::

    OUT/data/rigid/<data set>_seed<seed>.csv
    OUT/config_rigid.toml
    OUT/truth_rigid.json       noise-free loads, status per point, timing, effect parameters

Data sets (names are keys of ``campaign.DATA_SETS``, so ``oof_battery.runner`` scores them):

``control``
    The lifting line with the rotor's own polars (right: nothing named).
``leading_edge_erosion``
    ``hidden_effects.erosion_rotor``: linear ramp from r/R 0.6, drag rise 0.010 and 10 %
    lift-slope loss at the tip (a plain numpy table change).
``uniform_table``
    ``hidden_effects.uniform_rotor``: every lifting table as at Re/Re_ref = 0.5 (skin-friction
    drag rise ∝ Re^-0.2, C_L,max loss per decade).
``rotational_augmentation``
    Stall delay in Lindenburg's form (ECN-C-04-036, 2004), :func:`lindenburg_rotor`:
    ΔC_L = 3.1 (Ωr/W)² (c/r)² (C_L,lin − C_L), (Ωr/W)² at the design tip-speed ratio 7.55
    with induction 1/3, C_L,lin = the table's attached-flow line, faded out linearly from
    25 to 45 deg; drag unchanged. calib's candidates are Snel, Du–Selig and
    Chaviaropoulos–Hansen: the factor (Ωr/W)² is another radial law.

Timing (2026-11-27, defaults, one process on a 2-core machine shared with other jobs): 63
points per data set in 70-105 s (1.1-1.7 s per point), the four data sets with 20 seeds in
about 6 min; every point converged. Points 27 and 58 (λ 9.5, pitch −2 deg, 9 and 6 rpm) have
ā = 0.58 and carry a warning in the truth JSON (outside the helix model's validity; kept so the
operating points are the battery's).

calib's diagnosis on these data (20 seeds each, the written config, ``oof_battery.runner``;
``benchmarks/data/lifting_line/battery_rigid/diagnosis_2026-11-27.md``): ``control`` named
``tip_loss`` in 19 of 20 seeds (``rotational_augmentation`` in 1), never
``wind_tunnel_blockage``; the three effects were named right first in 20 of 20 each (alone in
10, 3 and 4 of 20 for rotational augmentation, uniform table and erosion). The control made
with a faster wake (``--wake-induction-factor 0.85``: LL/BEM power 1.063, thrust 1.037 at the
design point, like the reviewer's code) is named ``wind_tunnel_blockage`` in 20 of 20.

Run::

    PYTHONPATH=. .venv/bin/python benchmarks/lifting_line.py battery --seeds 20 --out bench_output/lifting_line_battery
"""

from __future__ import annotations

import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import lifting_line as ll  # noqa: E402
from oof_battery import campaign  # noqa: E402
from oof_battery import hidden_effects as hx  # noqa: E402

SETUP = "rigid"
#: First noise seed (seed of copy k: SEED0 + k); CCBlade's battery uses 25000 + k.
SEED0 = 26000
#: Lindenburg (2004) constant and the fade-out window of the augmentation [deg].
LINDENBURG_CONSTANT = 3.1
FADE_DEG = (25.0, 45.0)
DESIGN_TSR = hx.DESIGN_TSR
DATA_SETS = {
    "control": "the lifting line with the rotor's own polars",
    "leading_edge_erosion": ("hidden_effects.erosion_rotor: ramp from r/R 0.6, drag +0.010 and lift slope -10 % "
                             "at the tip"),
    "uniform_table": "hidden_effects.uniform_rotor: every lifting table as at Re/Re_ref = 0.5",
    "rotational_augmentation": "Lindenburg (2004) stall delay, 3.1 (Ωr/W)² (c/r)² (C_L,lin − C_L), at λ = 7.55",
}


def attached_line(alpha, cl):
    """Zero-lift angle [deg] and slope [1/deg] of a table's attached-flow line (fit on α0 … α0 + 6 deg)."""
    a, c = np.asarray(alpha, float), np.asarray(cl, float)
    win = (a > -10.0) & (a < 10.0)
    a0 = float(np.interp(0.0, c[win], a[win])) if np.all(np.diff(c[win]) > 0) else \
        float(a[win][np.argmin(np.abs(c[win]))])
    fit = (a >= a0) & (a <= a0 + 6.0)
    slope = float(np.polyfit(a[fit], c[fit], 1)[0]) if fit.sum() >= 2 else 2 * math.pi * math.pi / 180.0
    return a0, slope


def lindenburg_rotor(rotor: dict, tsr: float = DESIGN_TSR) -> dict:
    """Each lifting station's table with Lindenburg's (2004) rotational augmentation of the lift.

    Parameters
    ----------
    rotor : dict
        Rotor JSON (``export_rotor.rotor_to_dict``).
    tsr : float
        Tip-speed ratio of (Ωr/W)² = 1 / (1 + ((1 − 1/3) R / (λ r))²) [-].

    Notes
    -----
    C_L + f (C_L,lin − C_L) with f = 3.1 (Ωr/W)² (c/r)² and C_L,lin = slope (α − α0) for
    α ≥ α0, weight 1 up to 25 deg and falling linearly to 0 at 45 deg; nothing for α < α0.
    Lindenburg, Modelling of rotational augmentation based on engineering considerations and
    measurements, ECN-RX-04-131 / EWEC 2004.
    """
    r, chord, tip = np.asarray(rotor["r"], float), np.asarray(rotor["chord"], float), float(rotor["tip_radius"])

    def change(alpha, cl, cd, k):
        if not hx.is_lifting(cl) or not float(rotor["hub_radius"]) < r[k] < tip:
            return cl, cd
        a0, slope = attached_line(alpha, cl)
        speed2 = 1.0 / (1.0 + ((1.0 - 1.0 / 3.0) * tip / (tsr * r[k])) ** 2)
        f = LINDENBURG_CONSTANT * speed2 * (chord[k] / r[k]) ** 2
        w = np.interp(alpha, [a0, FADE_DEG[0], FADE_DEG[1]], [1.0, 1.0, 0.0], left=0.0, right=0.0)
        lin = slope * (alpha - a0)
        return cl + f * w * np.maximum(lin - cl, 0.0), cd
    return hx.per_station(rotor, change)


def rotor_of(name: str, rotor: dict) -> dict:
    """The rotor dict of data set ``name`` (polars changed by its hidden effect)."""
    makers = {"control": lambda x: x, "leading_edge_erosion": hx.erosion_rotor,
              "uniform_table": hx.uniform_rotor, "rotational_augmentation": lindenburg_rotor}
    if name not in makers:
        raise ValueError(f"unknown data set {name!r}; valid: {', '.join(makers)}")
    return makers[name](rotor)


def truth(names, settings: ll.LiftingLineSettings = ll.LiftingLineSettings(), say=print) -> dict:
    """Noise-free lifting-line loads of each data set at the battery's points.

    Raises
    ------
    RuntimeError
        When a point did not converge (listed with its reason): no data are written from it.
    """
    from calib.rotor.library import load_rotor  # noqa: PLC0415

    pts = campaign.operating_points(load_rotor("nrel5mw").rotor_radius)
    base = ll.load_nrel5mw_rigid()
    out = {"points": pts, "settings": dataclasses.asdict(settings), "data_sets": {}}
    for name in names:
        t0 = time.perf_counter()
        blade = ll.blade_from_rotor_dict(rotor_of(name, base))
        res = ll.solve_points(blade, pts["wind_speed"], pts["rotor_speed_rpm"], pts["pitch_deg"], settings,
                              float(base["rotor_radius"]))
        bad = [(k, res["message"][k]) for k, s in enumerate(res["status"]) if s != ll.CONVERGED]
        seconds = time.perf_counter() - t0
        warn = [k for k, w in enumerate(res["warning"]) if w]
        say(f"[lifting line battery] {name}: {len(pts['wind_speed'])} points in {seconds:.0f} s "
            f"({seconds / len(pts['wind_speed']):.2f} s per point), {len(bad)} not converged, "
            f"{len(warn)} with ā >= {ll.HIGH_INDUCTION:g} (points {warn}: kept, see truth JSON 'warnings')")
        if bad:
            raise RuntimeError(f"lifting line did not converge in data set {name} at points "
                               + "; ".join(f"{k} (λ {pts['tsr'][k]:.2f}, pitch {pts['pitch_deg'][k]:g}, "
                                           f"{pts['rotor_speed_rpm'][k]:g} rpm): {m}" for k, m in bad))
        out["data_sets"][name] = {**{c: res[c] for c in campaign.CHANNELS},
                                  "root_flap_moment": res["root_flap_moment"], "status": res["status"],
                                  "iterations": res["iterations"], "wake_iterations": res["wake_iterations"],
                                  "mean_axial_induction": res["mean_axial_induction"], "seconds": seconds,
                                  "warnings": {str(k): w for k, w in enumerate(res["warning"]) if w},
                                  "describe": DATA_SETS[name]}
    return out


def write_csv(tr: dict, name: str, seed: int, path: Path) -> Path:
    """One data set's CSV: 1 % noise of seed ``seed`` on the lifting-line truth (``generate.noisy_csv``)."""
    from oof_battery.generate import noisy_csv  # noqa: PLC0415

    d = tr["data_sets"][name]
    y = np.column_stack([np.asarray(d[c], float) for c in campaign.CHANNELS])
    return noisy_csv(y, tr["points"], seed, f"benchmarks/lifting_line.py: steady lifting line, prescribed helical "
                     f"wake, set-up {SETUP}, data set {name}, noise seed {seed}", path)


def reusable_truth(path: Path, names, settings: ll.LiftingLineSettings) -> dict | None:
    """The truth JSON at ``path`` when it holds every data set of ``names`` with the same settings, operating
    points and descriptions (the lifting line is deterministic: the same loads again), else None.

    A truth made by another version of ``lifting_line.py`` with the same settings is reused too: delete
    the file (or write to a new folder) after changing the solver.
    """
    from calib.rotor.library import load_rotor  # noqa: PLC0415

    try:
        tr = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    pts = campaign.operating_points(load_rotor("nrel5mw").rotor_radius)
    same_points = all(np.allclose(np.asarray(tr["points"][k], float), np.asarray(v, float), rtol=0, atol=0)
                      for k, v in pts.items() if k in tr.get("points", {}))
    sets = tr.get("data_sets", {})
    if (tr.get("settings") != json.loads(json.dumps(dataclasses.asdict(settings))) or not same_points
            or any(n not in sets or sets[n].get("describe") != DATA_SETS[n] for n in names)):
        return None
    return {**tr, "data_sets": {n: sets[n] for n in names}}


def write_battery(n_seeds: int, out: Path, names=None, say=print,
                  settings: ll.LiftingLineSettings = ll.LiftingLineSettings()) -> dict:
    """Truth, ``n_seeds`` noisy CSVs per data set and ``config_rigid.toml`` under ``out``.

    ``settings`` other than the defaults make a sensitivity study (e.g. a faster wake), not
    the battery's truth.

    Returns
    -------
    dict
        ``files`` [(set-up, data set, seed, path)] (the form ``oof_battery.runner.run_battery``
        takes), ``configs`` {set-up: path}, ``truth`` path, ``seconds``.
    """
    from oof_battery.generate import config_text  # noqa: PLC0415

    t0 = time.perf_counter()
    out = Path(out)
    names = list(names or DATA_SETS)
    tr = reusable_truth(out / f"truth_{SETUP}.json", names, settings)
    if tr is None:
        tr = truth(names, settings, say=say)
    else:
        say(f"[lifting line battery] truth reused from {out / f'truth_{SETUP}.json'} (same settings, points and "
            "data sets; the solves are deterministic)")
    out.mkdir(parents=True, exist_ok=True)
    (out / f"truth_{SETUP}.json").write_text(json.dumps(tr))
    files = []
    for name in names:
        for k in range(n_seeds):
            seed = SEED0 + k
            path = out / "data" / SETUP / f"{name}_seed{seed}.csv"
            files.append((SETUP, name, seed, write_csv(tr, name, seed, path)))
    cfg = out / f"config_{SETUP}.toml"
    cfg.write_text(config_text(SETUP).replace("# Written by benchmarks/oof_battery/generate.py; the same set-up as "
                                              "the CCBlade run of the data.",
                                              "# Written by benchmarks/lifting_line_battery.py; the same set-up as "
                                              "the lifting-line run of the data."))
    say(f"[lifting line battery] {len(names)} data sets x {n_seeds} seeds written to {out / 'data' / SETUP}; "
        f"config {cfg}")
    return {"files": files, "configs": {SETUP: cfg}, "truth": out / f"truth_{SETUP}.json",
            "seconds": time.perf_counter() - t0}
