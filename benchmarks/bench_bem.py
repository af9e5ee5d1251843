"""Native BEM speed: the NREL 5-MW C_P(λ, β) surface and the full Jacobian.

(a) the surface of :mod:`surface_grid` (2200 points) in one vectorized call;
(b) the exact Jacobian with respect to 86 parameters (2 × 7 α-nodes × 6 η-nodes of
    corrections, pitch offset, wind-speed scale) over 200 operating points, against one
    evaluation of the same points;
(c) the same with each effect of the library added to the chain (its parameters at
    non-nominal values): evaluation and Jacobian times and their ratio.
Times are the best of several repeats (perf_counter); ratios are taken within this run.
"""

from __future__ import annotations

import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(__file__))

from surface_grid import surface_grid, surface_points  # noqa: E402

from calib.bem import BemSettings, SectionPolars, solve_bem  # noqa: E402
from calib.corrections import CorrectionGrid  # noqa: E402
from calib.effects import make_effect  # noqa: E402
from calib.models.base import OperatingConditions
from calib.types import nominal_vector
from calib.models.bem_model import BemModel  # noqa: E402
from calib.rotor.library import load_rotor  # noqa: E402


EFFECT_VALUES = {"rotational_augmentation": [0.8], "leading_edge_erosion": [0.75, 0.01, 0.1],
                 "reynolds_number": [0.3, 0.2], "tip_loss": [0.7], "wind_tunnel_blockage": [0.1]}
"""Parameter values of each library effect in part (c)."""


def best_of(fn, repeats=5):
    best = np.inf
    out = None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def run(repeats: int = 5) -> dict:
    rotor = load_rotor("nrel5mw")
    settings = BemSettings(use_tilt=False, n_sectors=1)     # axisymmetric surface, as the CCBlade run
    polars = SectionPolars.from_rotor(rotor)
    tsr, pitch, rpm = surface_grid()
    v, om, beta = surface_points(tsr, pitch, rpm, rotor.rotor_radius)
    cond = OperatingConditions(v, om, beta)
    t_surface, res = best_of(lambda: solve_bem(rotor, cond, settings, polars=polars), repeats)
    cp = res.cp.reshape(tsr.size, pitch.size)

    grid = CorrectionGrid(np.linspace(-6.0, 18.0, 7), np.linspace(0.1, 1.0, 6))
    model = BemModel(rotor, grid, ("power", "thrust", "root_flap_moment", "root_edge_moment"), settings)
    rng = np.random.default_rng(1)
    wind = rng.uniform(4.0, 24.0, 200)
    sch = rotor.schedule
    rpm_pts = np.clip(sch.design_tsr * wind / rotor.rotor_radius * 30 / np.pi, sch.min_rotor_speed,
                      sch.max_rotor_speed)
    jcond = OperatingConditions(wind, rpm_pts, np.clip(1.6 * (wind - 11.4), 0, None))
    p = nominal_vector(model.parameters)
    t_eval, ev = best_of(lambda: model.evaluate(p, jcond), repeats)
    t_jac, (_, G) = best_of(lambda: model.jacobian(p, jcond), repeats)
    effects = {}
    for name, values in EFFECT_VALUES.items():
        m = BemModel(rotor, grid, ("power", "thrust", "root_flap_moment", "root_edge_moment"), settings,
                     effects=[make_effect(name)])
        pe = nominal_vector(m.parameters)
        pe[-len(values):] = values
        te, _ = best_of(lambda: m.evaluate(pe, jcond), repeats)
        tj, _ = best_of(lambda: m.jacobian(pe, jcond), repeats)
        effects[name] = {"eval_seconds": te, "jacobian_seconds": tj, "jacobian_over_eval": tj / te}
    return {"effects": effects,
            "native_surface_seconds": t_surface, "n_points": int(cond.n_points), "cp": cp, "tsr": tsr,
            "pitch": pitch, "surface_failed": int(res.n_failed), "cp_max": float(np.nanmax(cp)),
            "native_points_per_second": cond.n_points / t_surface,
            "eval_seconds": t_eval, "jacobian_seconds": t_jac, "jacobian_points": int(jcond.n_points),
            "jacobian_params": int(G.shape[2]), "jacobian_channels": int(G.shape[1]),
            "jacobian_over_eval": t_jac / t_eval, "jacobian_failed": int(ev.n_failed)}


if __name__ == "__main__":
    out = run()
    print(f"native surface: {out['n_points']} points in {out['native_surface_seconds'] * 1e3:.1f} ms "
          f"({out['native_points_per_second']:.0f} points/s), failed {out['surface_failed']}, "
          f"max C_P {out['cp_max']:.4f}")
    print(f"Jacobian {out['jacobian_points']} points x {out['jacobian_channels']} channels x "
          f"{out['jacobian_params']} params: {out['jacobian_seconds'] * 1e3:.1f} ms; one evaluation "
          f"{out['eval_seconds'] * 1e3:.1f} ms; ratio {out['jacobian_over_eval']:.2f} (target <= 3)")
    for name, e in out["effects"].items():
        print(f"  + {name:24s} evaluation {e['eval_seconds'] * 1e3:6.1f} ms, Jacobian "
              f"{e['jacobian_seconds'] * 1e3:6.1f} ms, ratio {e['jacobian_over_eval']:.2f}")
