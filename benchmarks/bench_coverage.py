"""Coverage of the 95 % polar bands and NEES in twin experiments (statistics, not speed).

Set-up of ``workflows/wind_tunnel_hub_loads.toml`` (NREL Phase VI rotor at 72 rpm, 72
tip-speed-ratio × pitch points, power and thrust with 1 % noise, 6 × 5 correction nodes
and a pitch offset; truth pitch offset 0.2 deg), two truths:

(a) inside the span of the shape functions: the workflow's smooth correction sampled at the
    calibration nodes (the calibrated model can represent it exactly);
(b) outside it: the same smooth field sampled on a 1 deg × 0.025 grid (as the workflow).

For ``n_seeds`` noise seeds (5000 + k; the test suite uses none of them) each calibration
runs with the default settings (``sigma_bar = "auto"``, prior 1 scale unit). Figures: the
fraction of the (α, η) points the operating points reach where the 95 % band contains the
true ΔC_L and ΔC_D (mean, 10th and 90th percentile over seeds), the summed NEES of the
retained θ against its two-sided 95 % χ² band, the retained count, failures and time.
Run: ``python benchmarks/bench_coverage.py [n_seeds]`` (about 10 s per calibration here).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy import stats

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.workflow import _conditions, load_workflow, smooth_field, truth_model

WORKFLOW = "workflows/wind_tunnel_hub_loads.toml"
SEED0 = 5000


def _setup():
    import os

    cfg = load_workflow(os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), WORKFLOW))
    rotor = load_rotor(cfg["rotor"]["name"])
    settings = BemSettings(use_tilt=False)
    channels = list(cfg["stages"][0]["channels"])
    cond = _conditions(cfg["conditions"], rotor, WORKFLOW)
    g = cfg["grid"]
    grid = CorrectionGrid(g["alpha_nodes_deg"], g["eta_nodes"])
    model = BemModel(rotor, grid, channels, settings, ("pitch_offset",))
    return cfg, rotor, settings, channels, cond, grid, model


def run(n_seeds: int = 30) -> dict:
    cfg, rotor, settings, channels, cond, grid, model = _setup()
    bumps = cfg["truth"]["bumps"]
    rel = {c: float(cfg["noise"]["relative"][c]) for c in channels}
    field = model.correction_field()
    # (b) outside the span: the workflow's fine-grid truth model
    tmodel_b, p_b = truth_model(rotor, channels, settings, cfg["truth"], ("pitch_offset",))
    # (a) inside the span: the smooth field at the calibration nodes
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    dl, dd = smooth_field(bumps, A, E)
    p_a = np.zeros(len(model.parameters))
    p_a[:grid.n_lift], p_a[grid.n_lift:grid.n_params] = dl.ravel(), dd.ravel()
    p_a[-1] = float(cfg["truth"].get("pitch_offset", 0.0))
    out = {}
    for label, tmodel, p_true in (("a_inside_span", model, p_a), ("b_outside_span", tmodel_b, p_b)):
        lift, drag, nees, dims, kept, failed = [], [], [], [], [], 0
        t0 = time.perf_counter()
        for k in range(n_seeds):
            meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels, seed=SEED0 + k)
            res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003)).run()
            if res.status != "converged":
                failed += 1
            a, e = res.alpha_seen, res.eta_seen
            if tmodel is model:
                tl, td = field.basis(a, e, "lift") @ p_true, field.basis(a, e, "drag") @ p_true
                theta_true = res.V[:, res.retained].T @ ((p_true - res.p_nominal) / res.scale)
                err = res.theta_hat - theta_true
                nees.append(float(err @ np.linalg.solve(res.cov_theta, err)) if err.size else 0.0)
                dims.append(err.size)
            else:
                tl, td = smooth_field(bumps, a, e)
            cov = field.coverage(res.p_hat, res.cov_p, a, e, tl, td, prior_std=res.prior_std)
            lift.append(cov["lift"])
            drag.append(cov["drag"])
            kept.append(res.n_retained)
            print(f"[coverage {label}] seed {SEED0 + k}: lift {cov['lift']:.3f} drag {cov['drag']:.3f} "
                  f"retained {res.n_retained} {res.status}", flush=True)
        fig = {"coverage_lift_mean": float(np.mean(lift)), "coverage_drag_mean": float(np.mean(drag)),
               "coverage_lift_p10_p90": np.percentile(lift, [10, 90]).tolist(),
               "coverage_drag_p10_p90": np.percentile(drag, [10, 90]).tolist(),
               "retained_min_max": [int(min(kept)), int(max(kept))], "not_converged": failed,
               "seconds_per_calibration": (time.perf_counter() - t0) / n_seeds}
        if dims:
            lo, hi = stats.chi2.ppf([0.025, 0.975], int(np.sum(dims)))
            fig.update({"nees_sum": float(np.sum(nees)), "nees_band": [float(lo), float(hi)],
                        "nees_dof": int(np.sum(dims))})
        out[label] = fig
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run(int(sys.argv[1]) if len(sys.argv) > 1 else 30), indent=1))
