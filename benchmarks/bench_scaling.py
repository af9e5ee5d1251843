"""Cost against campaign size: the wind-tunnel study on denser operating grids.

The set-up of ``workflows/wind_tunnel_hub_loads.toml`` (NREL Phase VI rotor at 72 rpm, power and
thrust with 1 % noise, 6 × 5 correction nodes and a pitch offset; its smooth truth on the fine
grid, pitch offset 0.2°), with the tip-speed ratio × pitch grid refined: 12 × 6 = 72 points (the
workflow), 36 × 18 = 648 and 72 × 36 = 2592 over the same ranges. Each size is calibrated with
the default settings of each estimator once (wall and CPU seconds (``time.process_time``, this
process), a time per point, the Gauss–Newton iterations (every fit), the model calls, the status
and χ²/dof); a linear cost gives the same seconds per point at every size. The truncated estimator's
largest size is skipped unless ``--all`` (221 s there before the MAP estimator existed).

Run: ``python benchmarks/bench_scaling.py [--all]`` (make bench).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

import numpy as np

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.workflow import load_workflow, synthetic_conditions, truth_model

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WORKFLOW = "workflows/wind_tunnel_hub_loads.toml"
SIZES = ((12, 6), (36, 18), (72, 36))


def _case(n_tsr: int, n_pitch: int):
    workflow = load_workflow(os.path.join(ROOT, WORKFLOW))
    rotor = load_rotor(workflow.rotor["name"])
    settings = BemSettings(use_tilt=False)
    channels = list(workflow.stages[0].channels)
    c = workflow.conditions
    c = dataclasses.replace(c, tsr=tuple(np.linspace(min(c.tsr), max(c.tsr), n_tsr).tolist()),
                            pitch=tuple(np.linspace(min(c.pitch), max(c.pitch), n_pitch).tolist()))
    cond = synthetic_conditions(c, rotor)
    g = workflow.grid
    model = BemModel(rotor, CorrectionGrid(g.alpha_nodes_deg, g.eta_nodes), channels, settings,
                     nuisance=("pitch_offset",))
    tmodel, p_true = truth_model(rotor, channels, settings, workflow.truth, ("pitch_offset",))
    rel = {ch: float(workflow.noise.relative[ch]) for ch in channels}
    meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels, seed=workflow.noise.seed)
    return model, meas


def run(everything: bool = False) -> dict:
    out = {}
    for n_tsr, n_pitch in SIZES:
        model, meas = _case(n_tsr, n_pitch)
        n = len(meas.conditions)
        for estimator in ("map", "truncated"):
            if estimator == "truncated" and n > 1000 and not everything:
                continue
            records = []
            t, cpu = time.perf_counter(), time.process_time()
            res = Calibrator(model, meas, CalibrationSettings(estimator=estimator, cd_min=0.003),
                             callback=records.append).run()
            wall, cpu = time.perf_counter() - t, time.process_time() - cpu
            rec = {"points": n, "seconds": wall, "cpu_seconds": cpu, "ms_per_point": 1e3 * wall / n,
                   "iterations": sum(1 for r in records if "damping" in r), "status": res.estimate.status,
                   "retained": res.n_retained, "chi2_per_dof_after": res.fit.chi2_after / res.dof,
                   "model_jacobians": res.fit.failures["model_jacobians"],
                   "model_evaluations": res.fit.failures["model_evaluations"]}
            out[f"{estimator}_{n}"] = rec
            print(f"[scaling] {estimator} {n} points: {wall:.1f} s ({rec['ms_per_point']:.1f} ms/point, "
                  f"{cpu:.1f} s CPU), {res.estimate.status}, {rec['iterations']} iterations, "
                  f"{rec['model_jacobians']} Jacobians", flush=True)
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run("--all" in sys.argv), indent=1))
