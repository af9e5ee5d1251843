"""Campaign design through the bundled FMU: predicted = realized (issue 39, acceptance "on the bundled FMU").

The problem (small enough for 100 MAP fits through the FMU): the bundled turbine FMU (variant A, NREL
5-MW, quasi-steady: rigid blades, no tower, shear or dynamic inflow; Snel's stall delay on; the bundled
workflow's short averaging), its four scalar parameters (the three blade pitch offsets and the stall-delay
strength, no correction field), four channels (power, thrust, root flap moment of blades 1 and 2) at 1 % of
their RMS, the workflow's prior. Jacobians by forward differences at 0.1 × each parameter's scale, the
step the difference study of ``bench_fmu_run.py`` measured above the FMU's output jumps (CHANGELOG, issue 38).

1. ``calib design``'s default design (Bayesian D with the default discrepancy) of ``N`` = 6 points from a
   6 λ × 3 pitch candidate grid over the workflow's envelope (λ 4–10, pitch 0–3°, 10 rpm): the FMU's
   sensitivities once, through the workflow's process executor (2 workers).
2. At the truth (the nominal parameters, where the design linearized), ``reps`` noise replicates at the
   chosen points, each calibrated by calib's MAP estimator through the FMU (its Jacobians by the same
   differences). Along each direction of the prior-whitened parameters the design determines (s > 1),
   the realized spread of the estimates against the design's prediction, as in ``bench_design.py``: the
   linear-Gaussian spread of a MAP estimate at a fixed truth s/(1 + s²) and the posterior σ 1/√(1 + s²);
   and the Laplace σ the calibration itself reports at each estimate, along the same directions
   (its median over the replicates).

Every replicate's estimate is appended to ``bench_output/design_fmu/replicates.jsonl`` as it finishes, so
a killed run resumes where it stopped (``--fresh`` starts over; :func:`run`, as ``make validate`` calls
it, always does). ``python benchmarks/bench_design_fmu.py [REPS] [--fresh]`` (default 100); :func:`run`
publishes ``design_fmu``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)
sys.path.insert(0, HERE)

from bench_fmu_run import _toml  # noqa: E402  (the workflow TOML writer of the FMU run benchmark)

SUITE = "validate"
OUT = Path(ROOT) / "bench_output" / "design_fmu"
PARAMETERS = ["pitch_offset_blade1", "pitch_offset_blade2", "pitch_offset_blade3", "stall_delay_strength"]
CHANNELS = ["power", "thrust", "root_flap_moment_blade1", "root_flap_moment_blade2"]
SWITCHES = dict(tower_shadow=False, shear=False, yaw=False, flexible_blades=False, gravity=False,
                skewed_wake=False, dynamic_inflow=False, tip_loss=True, hub_loss=True, stall_delay="snel")
STEADY = dict(steps_per_revolution=12, settle_revolutions=1, average_revolutions=2)
JACOBIAN = dict(differences="forward", relative_step=0.1)
N = 6
GRID = (6, 3)
SEED = 3900


def workflow(out: Path = OUT) -> Path:
    """The workflow file of the study (written into ``out``); its synthetic ``[conditions]`` span the
    envelope and set the noise levels (1 % of each channel's RMS there)."""
    out.mkdir(parents=True, exist_ok=True)
    wf = out / "design_fmu.toml"
    wf.write_text("\n".join([
        'name = "bench_design_fmu"',
        'description = "issue 39: predicted = realized through the bundled FMU, 4 parameters, 4 channels"',
        "[rotor]", 'name = "nrel5mw"',
        "[model]", 'kind = "fmu"', 'variant = "A"', f"parameters = {_toml(PARAMETERS)}", "corrections = false",
        f"switches = {_toml(SWITCHES)}", "settings = { shaft_tilt = 0.0 }", f"steady = {_toml(STEADY)}",
        f"jacobian = {_toml(JACOBIAN)}",
        "[grid]", "alpha_nodes_deg = [4.0, 10.0, 16.0]", "eta_nodes = [0.6, 1.0]",
        "[conditions]", "tsr = [4.0, 5.5, 7.0, 8.5, 10.0]", "pitch = [0.0, 3.0]", "rotor_speed = 10.0",
        "air_density = 1.225",
        "[truth]", "pitch_offset = 0.0",      # the synthetic data (unused: the study's truth is the FMU's own)
        "[[truth.bumps]]", 'block = "lift"', "amplitude = -0.08", "alpha_deg = 11.0", "alpha_width = 4.0",
        "eta = 0.85", "eta_width = 0.25",
        "[noise]", f"relative = {_toml({c: 0.01 for c in CHANNELS})}", "seed = 7",
        "[executor]", 'kind = "process"', "workers = 2",
        "[[stages]]", 'name = "rotor_loads"', f"channels = {_toml(CHANNELS)}", ""]))
    return wf


def map_settings(problem, workflow_path):
    """The workflow's calibration settings for a MAP fit at the problem's known noise (nothing beyond the
    estimate and its Laplace covariance)."""
    from calib.workflow.schema import load_workflow
    from calib.workflow.setup import prepare

    setup = prepare(load_workflow(workflow_path))
    sig = dict(zip(problem.channels, map(float, problem.sigma)))
    return dataclasses.replace(setup.calibration, estimator="map", noise="known", sigma=sig,
                               representation_error=False, curvature_samples=0, tightening=False,
                               prior_check=False, scale_by_fit=False)


def fit(problem, settings, cond, clean, rng):
    """One MAP calibration from ``clean`` plus noise: (p̂, its Laplace covariance, status, simulations)."""
    from calib.calibration.calibrator import Calibrator
    from calib.measurements import Measurements

    before = problem.model.simulation_summary()["simulations"]
    y = clean + rng.normal(size=clean.shape) * problem.sigma
    m = Measurements(cond, tuple(problem.channels), y, sigma=np.broadcast_to(problem.sigma, y.shape).copy())
    res = Calibrator(problem.model, m, settings).run()
    return (np.asarray(res.estimate.p_hat, float), np.asarray(res.uncertainty.cov_p, float),
            str(res.estimate.status), int(problem.model.simulation_summary()["simulations"] - before))


def directions(problem, H, chosen):
    """The design's prior-whitened directions: s (descending) and the eigenvectors V (columns)."""
    from calib.design.select import precision

    F = precision(H, chosen) - np.eye(len(problem.names))
    lam, V = np.linalg.eigh(0.5 * (F + F.T))
    order = np.argsort(lam)[::-1]
    return np.sqrt(np.clip(lam[order], 0, None)), V[:, order]


def whitened(problem, P):
    """Estimates P (reps, n) [parameter units] in the prior-whitened coordinates about the truth."""
    E = (np.asarray(P, float) - problem.p) / problem.scale
    return np.linalg.solve(problem.L, E.T).T


def laplace_along(problem, covs, V):
    """The Laplace σ along each whitened direction (columns of V) of each covariance (reps, n, n)
    [parameter units²]: √(vᵀ L⁻¹ D⁻¹ C D⁻¹ L⁻ᵀ v), shape (reps, k)."""
    D = 1.0 / problem.scale
    Li = np.linalg.inv(problem.L)
    W = Li @ (np.asarray(covs) * D[None, :, None] * D[None, None, :]) @ Li.T
    return np.sqrt(np.clip(np.einsum("ik,rij,jk->rk", V, W, V), 0, None))


def run_bench(reps: int = 100, fresh: bool = False) -> dict:
    from calib.design import design, problem_from_workflow
    from calib.design.candidates import generate

    wf = workflow()
    store = OUT / "replicates.jsonl"
    if fresh and store.exists():
        store.unlink()
    t0 = time.process_time()
    problem = problem_from_workflow(wf)
    try:
        cands = generate(problem.envelope, *GRID)
        t = time.process_time()
        res = design(problem, N, cands)
        sims_design = int(problem.model.simulation_summary()["simulations"])
        t_design = time.process_time() - t
        cond = cands.subset(res.design)
        clean = problem.model.evaluate(problem.p, cond).values
        settings = map_settings(problem, wf)
        done = [json.loads(line) for line in store.read_text().splitlines()] if store.exists() else []
        for k in range(len(done), reps):
            p, cov, status, sims = fit(problem, settings, cond, clean, np.random.default_rng(SEED + k))
            row = {"replicate": k, "p_hat": p.tolist(), "cov": cov.tolist(), "status": status, "simulations": sims}
            with store.open("a") as fh:
                fh.write(json.dumps(row) + "\n")
            done.append(row)
            print(f"[design_fmu] replicate {k + 1}/{reps}: {status}, {sims} simulations", flush=True)
        design_sims = sims_design
    finally:
        problem.close()
    done = done[:reps]
    s, V = directions(problem, res.H, res.design)
    det = s > 1
    W = whitened(problem, [r["p_hat"] for r in done])
    realized = np.sqrt(np.mean((W @ V[:, det]) ** 2, axis=0))
    lap = laplace_along(problem, [r["cov"] for r in done], V[:, det])
    post, freq = 1 / np.sqrt(1 + s[det] ** 2), s[det] / (1 + s[det] ** 2)
    status = {}
    for r in done:
        status[r["status"]] = status.get(r["status"], 0) + 1
    return {"budget": N, "candidates": int(len(cands)), "failed_candidates": res.n_failed,
            "parameters": problem.names, "channels": problem.channels, "jacobian": JACOBIAN,
            "design_points": [{"tsr": float(a), "pitch": float(b)} for a, b in
                              zip(cond.tip_speed_ratio(problem.envelope.radius), cond.pitch)],
            "s": s.tolist(), "directions": int(det.sum()), "replicates": len(done), "status": status,
            "realized": realized.tolist(), "ratio_to_linear_spread": (realized / freq).tolist(),
            "ratio_to_posterior": (realized / post).tolist(),
            "laplace_median_over_linear_spread": (np.median(lap, axis=0) / freq).tolist(),
            "laplace_median_over_posterior": (np.median(lap, axis=0) / post).tolist(),
            "mean_whitened": np.mean(W @ V[:, det], axis=0).tolist(),
            "cpu_design_s": t_design, "simulations_design": design_sims,
            "simulations_per_fit_median": float(np.median([r["simulations"] for r in done])),
            "cpu_total_s": time.process_time() - t0}


def markdown(out: dict) -> str:
    pts = ", ".join(f"({p['tsr']:.1f}, {p['pitch']:.1f}°)" for p in out["design_points"])
    rows = [f"The bundled FMU (variant A), {len(out['parameters'])} parameters, {len(out['channels'])} channels at "
            f"1 %: the default design of {out['budget']} points from {out['candidates']} candidates (λ, pitch: {pts}); "
            f"{out['replicates']} noise replicates at the truth, each a MAP calibration through the FMU "
            f"(statuses: " + ", ".join(f"{k} {v}" for k, v in out["status"].items()) + ").", "",
            "| direction | s | realized / linear-Gaussian spread | realized / posterior σ | "
            "Laplace σ at the estimates / linear-Gaussian spread |", "|---|---|---|---|---|"]
    for k in range(out["directions"]):
        rows.append(f"| {k + 1} | {out['s'][k]:.2f} | {out['ratio_to_linear_spread'][k]:.2f} | "
                    f"{out['ratio_to_posterior'][k]:.2f} | {out['laplace_median_over_linear_spread'][k]:.2f} |")
    return "\n".join(rows) + "\n"


def run(reps: int = 100, fresh: bool = True) -> dict:
    """Entry point of ``benchmarks/run_all.py``: the study, published for the validation page (from scratch;
    the command line resumes unless given ``--fresh``)."""
    from publish import command_line, publish

    out = run_bench(reps, fresh)
    publish("design_fmu", out, command_line(), markdown(out))
    return out


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    print(markdown(run(int(args[0]) if args else 100, "--fresh" in sys.argv)))
