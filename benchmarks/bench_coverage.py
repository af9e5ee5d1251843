"""Coverage of the 95 % polar bands, NEES, and the held-back error of the automatic truncation
(statistics, not speed).

Coverage twins: the set-up of ``workflows/wind_tunnel_hub_loads.toml`` (NREL Phase VI rotor at
72 rpm, 72 tip-speed-ratio × pitch points, power and thrust with 1 % noise, 6 × 5 correction
nodes and a pitch offset; truth pitch offset 0.2 deg), two truths:

(a) inside the span of the shape functions: the workflow's smooth correction sampled at the
    calibration nodes (the calibrated model can represent it exactly);
(b) outside it: the same smooth field sampled on a 1 deg × 0.025 grid (as the workflow);
(c) a check of the bands themselves: a truth drawn, for each seed, from the stated prior
    (the smooth-field prior of ``calib.calibration.settings.CalibrationSettings``: 1 scale unit per
    node, correlation length one node spacing) at the calibration nodes, pitch offset 0.2 deg.
    Draws that make C_D < C_D,min (the calibration's bound, 0.003) at a reached section are
    drawn again (the prior conditioned on the polars the calibration states possible; its drag
    bands are bounded there too).
    For truths typical of the prior the 95 % bands should cover about 95 %; (a) and (b) are
    two particular truths, zero where the operating points say little.
(d) a truth outside the span drawn from the same prior: a stationary field on the truth
    model's 1 deg × 0.025 grid whose samples at the calibration nodes are the prior of (c), so
    it also varies between the nodes as the representation variance and the aliasing term of
    :mod:`calib.parametrizations.aliasing` assume (:func:`_fine_prior_draw`).

For ``n_seeds`` noise seeds (5000 + k; the test suite uses none of them, and none was used to
choose the method) each calibration runs with the default settings (``sigma_bar = "auto"``,
prior 1 scale unit per node, smooth-field prior correlation of one node spacing). Figures: the
fraction of the (α, η) points the operating points reach where the 95 % band contains the true
ΔC_L and ΔC_D (mean over seeds, 10th and 90th percentile, and the pooled fraction), the same
inside the node range only, the summed NEES of the retained θ against its two-sided 95 % χ²
band (against the truth's values at the calibration nodes, with the covariance the result
states: noise, the field between the nodes, fit scale; also with the noise part alone), the
same over the calibrations that ended "converged" (the others listed), the prior check's
verdicts and how often its 95 % interval holds the stated amplitude 1 (:mod:`calib.checks.prior_check`;
in (d) the truth is drawn from the very prior the check assumes), the retained count, how often
the automatic choice started again and kept the second start (``second_start``), failures and
time.

Held-back truncation check: every third operating point held back (on the workflows' grids of
six pitch settings per tip-speed ratio, two whole pitch lines; on the twin, interleaved; for the
wind tunnel also an interleaved split, a third of every pitch line and tip-speed ratio),
calibrate on the rest with ``sigma_bar = "auto"`` and with σ̄ = 0.1 … 5, predict the held-back
points and compare χ²/dof (mean squared whitened residual) of the automatic choice with the
best of the sweep; on both shipped workflows (with their own noise seeds; the localization
study's stage 2) and on the analytic twin of ``tests/twin_model.py`` (56 points, truth of
``tests/test_calibration.py``).

Also, per twin: the NEES of the whole scaled parameter vector against the truth at the nodes
with the stated covariance, and the in-sample predictive check: measured against predicted at
the calibration points with σ² = noise² + prediction variance (χ² per row, χ² per degree of
freedom, i.e. over the rows less the parameters the fit used, and the fraction of rows inside the
95 % interval; far below 1 means bands wider than the data justify).

Run: ``python benchmarks/bench_coverage.py [n_seeds] [--no-held-back] [--estimator=map|truncated]`` (a few seconds per
calibration here; 30 seeds about 5–10 min, the held-back part about as long).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

import numpy as np
from scipy import stats

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.measurements import Measurements, synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.workflow import load_workflow, prepare, smooth_field, synthetic_conditions, truth_model

#: A statistical or soak study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
WORKFLOW = "workflows/wind_tunnel_hub_loads.toml"
SEED0 = 5000
SWEEP = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.5, 2.0, 3.0, 5.0)


def _setup():
    workflow = load_workflow(os.path.join(ROOT, WORKFLOW))
    rotor = load_rotor(workflow.rotor["name"])
    settings = BemSettings(use_tilt=False)
    channels = list(workflow.stages[0].channels)
    cond = synthetic_conditions(workflow.conditions, rotor)
    grid = CorrectionGrid(workflow.grid.alpha_nodes_deg, workflow.grid.eta_nodes)
    model = BemModel(rotor, grid, channels, settings, ("pitch_offset",))
    return workflow, rotor, settings, channels, cond, grid, model


def _physical(tmodel, p: np.ndarray, cond, cd_min: float | None) -> bool:
    """Whether a drawn truth is one the calibration's statements allow: every operating point
    converges (the BEM refuses C_D <= 0) and C_D >= ``cd_min`` (or the nominal C_D, where that
    is lower: :meth:`calib.parametrizations.CorrectionField.drag_floor`) at every section the
    operating points reach."""
    ev = tmodel.evaluate(p, cond)
    if not np.all(ev.ok):
        return False
    field = tmodel.correction_field()
    a, e = field.seen(ev)
    return bool(np.all(field.basis(a, e, "drag") @ p >= field.drag_floor(a, e, cd_min) - 1e-12))


def _prior_draw(model, grid, cond, seed: int, cd_min: float | None) -> np.ndarray:
    """Node values drawn from the default smooth-field prior, pitch offset 0.2 deg; draws that
    make C_D < ``cd_min`` somewhere at the operating points (:func:`_physical`) are drawn
    again: the prior conditioned on the bound the calibration states."""
    st = CalibrationSettings()
    std = np.array([q.scale * st.prior_sigma for q in model.parameters])
    P = model.correction_field().node_correlation(st.prior_correlation) * np.outer(std, std)
    n = grid.n_params
    rng = np.random.default_rng(seed)
    for _ in range(200):
        p = np.zeros(len(model.parameters))
        p[:n] = rng.multivariate_normal(np.zeros(n), P[:n, :n], method="eigh")
        p[-1] = 0.2
        if _physical(model, p, cond, cd_min):
            return p
    raise RuntimeError(f"no physical prior draw in 200 tries (seed {seed})")


def _fine_prior_draw(tmodel, model, grid, cond, seed: int, cd_min: float | None) -> np.ndarray:
    """Twin (d): a truth outside the span of the calibration's shape functions, drawn from the
    smooth-field prior itself (the stationary field whose samples at the calibration nodes are
    the prior of twin (c)) on the truth model's fine grid (1 deg × 0.025), pitch offset 0.2 deg.

    The field has variance (scale × ``prior_sigma``)² per block and the squared-exponential
    correlation of :meth:`calib.parametrizations.CorrectionField.node_correlation` with the
    calibration grid's lengths (one mean node spacing: 6 deg in α, 0.1875 in η), so it varies
    between the calibration nodes as the representation variance assumes. The kernel is
    separable, so a draw is L_α Z L_ηᵀ. Draws that make C_D < ``cd_min`` somewhere at the
    operating points are drawn again, as in (c)."""
    st = CalibrationSettings()
    fine = tmodel.correction_field().grid
    la, le = model.correction_field().correlation_lengths(st.prior_correlation)

    def root(x, length):
        K = np.exp(-0.5 * ((x[:, None] - x[None]) / length) ** 2)
        w, Q = np.linalg.eigh(K)
        return Q * np.sqrt(np.clip(w, 0.0, None))

    La, Le = root(fine.alpha_nodes_deg, la), root(fine.eta_nodes, le)
    # the calibration's prior 1-σ of a lift and of a drag node (scale × prior_sigma)
    sd = [model.parameters[0].scale * st.prior_sigma, model.parameters[grid.n_lift].scale * st.prior_sigma]
    rng = np.random.default_rng(seed)
    shape = (fine.alpha_nodes_deg.size, fine.eta_nodes.size)
    for _ in range(200):
        p = np.zeros(len(tmodel.parameters))
        for k in range(2):
            p[k * fine.n_lift:(k + 1) * fine.n_lift] = sd[k] * (La @ rng.standard_normal(shape) @ Le.T).reshape(-1)
        p[-1] = 0.2
        if _physical(tmodel, p, cond, cd_min):
            return p
    raise RuntimeError(f"no physical prior draw in 200 tries (seed {seed})")


def coverage(n_seeds: int = 30, seed0: int = SEED0, twins: str = "abcd", **calibration) -> dict:
    """Coverage of the polar bands and NEES over ``n_seeds`` noise seeds, twins (a)–(d);
    ``calibration`` overrides :class:`calib.calibration.settings.CalibrationSettings` fields (default
    ``cd_min = 0.003``)."""
    workflow, rotor, settings, channels, cond, grid, model = _setup()
    bumps = workflow.truth.bumps
    rel = {c: float(workflow.noise.relative[c]) for c in channels}
    field = model.correction_field()
    settings_cd_min = calibration.pop("cd_min", 0.003)
    # (b) outside the span: the workflow's fine-grid truth model
    tmodel_b, p_b = truth_model(rotor, channels, settings, workflow.truth, ("pitch_offset",))
    # (a) inside the span: the smooth field at the calibration nodes
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    dl, dd = smooth_field(bumps, A, E)
    p_a = np.zeros(len(model.parameters))
    p_a[:grid.n_lift], p_a[grid.n_lift:grid.n_params] = dl.ravel(), dd.ravel()
    p_a[-1] = float(workflow.truth.nuisance_values().get("pitch_offset", 0.0))
    a_lo, a_hi = grid.alpha_nodes_deg[[0, -1]]
    e_lo, e_hi = grid.eta_nodes[[0, -1]]
    out = {}
    cases = {"a": ("a_inside_span", model, p_a), "b": ("b_outside_span", tmodel_b, p_b),
             "c": ("c_prior_draws", model, None), "d": ("d_prior_draws_outside_span", tmodel_b, None)}
    for label, tmodel, p_fixed in (cases[t] for t in twins):
        cov = {"lift": [], "drag": [], "lift_in_grid": [], "drag_in_grid": []}
        hits = {"lift": [0, 0], "drag": [0, 0]}
        nees, nees_noise, dims, stable, kept, failed = [], [], [], [], [], 0
        prior_checks, second, fold_runs = [], [0, 0], 0
        full_nees, pred_chi2, pred_cover, pred_rows, pred_dof = [], 0.0, 0, 0, 0.0
        t0 = time.perf_counter()
        for k in range(n_seeds):
            if p_fixed is not None:
                p_true = p_fixed
            elif tmodel is model:
                p_true = _prior_draw(model, grid, cond, seed0 + k, settings_cd_min)
            else:
                p_true = _fine_prior_draw(tmodel, model, grid, cond, seed0 + k, settings_cd_min)
            meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels, seed=seed0 + k)
            res = Calibrator(model, meas, CalibrationSettings(cd_min=settings_cd_min, **calibration)).run()
            if res.estimate.status != "converged":
                failed += 1
            a, e = res.fit.alpha_seen, res.fit.eta_seen
            if tmodel is model:
                tl, td = field.basis(a, e, "lift") @ p_true, field.basis(a, e, "drag") @ p_true
                p_nodes = p_true
            elif p_fixed is None:
                tfield = tmodel.correction_field()
                tl, td = tfield.basis(a, e, "lift") @ p_true, tfield.basis(a, e, "drag") @ p_true
                p_nodes = res.estimate.p_nominal.copy()
                p_nodes[:grid.n_lift] = tfield.basis(A.ravel(), E.ravel(), "lift") @ p_true
                p_nodes[grid.n_lift:grid.n_params] = tfield.basis(A.ravel(), E.ravel(), "drag") @ p_true
                p_nodes[grid.n_params:] = p_true[-(len(p_nodes) - grid.n_params):]
            else:  # (b): the workflow's field, whose values at the nodes are (a)'s truth
                tl, td = smooth_field(bumps, a, e)
                p_nodes = p_a
            # the retained θ against the truth's values at the calibration nodes, with the
            # covariance the result states (noise, the field between the nodes at its
            # estimated size, fit scale) and with the noise part alone
            Vr = res.identifiability.V[:, res.identifiability.retained]
            err = Vr.T @ ((res.estimate.p_hat - p_nodes) / res.estimate.scale)
            C = Vr.T @ (res.uncertainty.cov_p / np.outer(res.estimate.scale, res.estimate.scale)) @ Vr
            nees.append(float(err @ np.linalg.solve(C, err)) if err.size else 0.0)
            nees_noise.append(float(np.sum((err / res.identifiability.sigma_theta[res.identifiability.retained]) ** 2)))
            # the whole scaled vector against the truth at the nodes (the posterior's own NEES)
            e_all = (res.estimate.p_hat - p_nodes) / res.estimate.scale
            full_nees.append(float(e_all @ np.linalg.lstsq(res.uncertainty.cov_p / np.outer(res.estimate.scale,
                                                                                            res.estimate.scale), e_all,
                                                           rcond=None)[0]))
            # in-sample predictive check: measured against predicted with σ² = noise² + prediction variance
            pred = res.predict(cond, model)
            ok = pred.status == 0
            sd = np.sqrt(res.fit.sigma ** 2 + pred.std ** 2)[ok]
            zz = ((meas.values - pred.values)[ok] / sd).ravel()
            pred_chi2 += float(np.sum(zz ** 2))
            # degrees of freedom: rows less the parameters the fit used (the MAP's effective number
            # Σ s²/(1 + s²), the truncated estimate's retained count)
            s_ = res.identifiability.singular_values
            fitted = float(np.sum(s_ ** 2 / (1.0 + s_ ** 2))) if res.estimator == "map" else res.n_retained
            pred_dof += zz.size - fitted
            pred_cover += int(np.sum(np.abs(zz) <= stats.norm.ppf(0.975)))
            pred_rows += zz.size
            dims.append(err.size)
            stable.append(res.estimate.status == "converged")
            rep = res.uncertainty.prior_std if res.provenance.settings.get("representation_error", True) else None
            length = res.provenance.settings.get("prior_correlation", 0.0)
            c = field.coverage(res.estimate.p_hat, res.uncertainty.cov_p, a, e, tl, td, prior_std=rep,
                               correlation_length=length,
                               cd_min=res.provenance.settings.get("cd_min"))
            inside = (a >= a_lo) & (a <= a_hi) & (e >= e_lo) & (e <= e_hi)
            ci = field.coverage(res.estimate.p_hat, res.uncertainty.cov_p, a[inside], e[inside], tl[inside],
                                td[inside], prior_std=rep,
                                correlation_length=length, cd_min=res.provenance.settings.get("cd_min"))
            for block in ("lift", "drag"):
                cov[block].append(c[block])
                cov[f"{block}_in_grid"].append(ci[block])
                hits[block][0] += round(c[block] * c["n_points"])
                hits[block][1] += c["n_points"]
            kept.append(res.n_retained)
            prior_checks.append(res.uncertainty.prior_check)
            if "second_retained" in res.identifiability.truncation:      # the automatic choice's second start
                second[0] += 1
                second[1] += int(res.identifiability.truncation["second_kept"])
            print(f"[coverage {label}] seed {seed0 + k}: lift {c['lift']:.3f} drag {c['drag']:.3f} (inside the node "
                  f"range {ci['lift']:.3f} {ci['drag']:.3f}) retained {res.n_retained} NEES {nees[-1]:.1f} "
                  f"fit scale {res.uncertainty.fit_scale:.2f} prior amplitude {res.uncertainty.prior_check['amplitude']:.2f} "
                  f"({res.uncertainty.prior_check['lower']:.2f}-{res.uncertainty.prior_check['upper']:.2f}) {res.estimate.status}"
                  + (f" fold θ {sorted({d['theta'] for d in res.identifiability.fold_directions})}" if res.identifiability.fold_directions else ""),
                  flush=True)
            fold_runs += bool(res.identifiability.fold_directions)
        fig = {"n_seeds": n_seeds, "seeds": [seed0, seed0 + n_seeds - 1]}
        for key, v in cov.items():
            fig[f"coverage_{key}_mean"] = float(np.mean(v))
            fig[f"coverage_{key}_p10_p90"] = np.percentile(v, [10, 90]).tolist()
        for block in ("lift", "drag"):
            fig[f"coverage_{block}_pooled"] = hits[block][0] / hits[block][1]
        # the prior check (calib.checks.prior_check): how often its interval holds the stated amplitude 1
        amp = np.array([pc["amplitude"] for pc in prior_checks])
        fig.update({"prior_check_contains_stated": float(np.mean([pc["lower"] <= 1.0 <= pc["upper"]
                                                                   for pc in prior_checks])),
                    "prior_check_verdicts": {v: sum(pc["verdict"] == v for pc in prior_checks)
                                             for v in ("consistent", "larger", "smaller")},
                    "prior_check_amplitude_median_p10_p90": [float(np.median(amp)),
                                                             *np.percentile(amp, [10, 90]).tolist()]})
        lo, hi = stats.chi2.ppf([0.025, 0.975], n_seeds * len(res.estimate.p_hat))
        fig.update({"estimator": res.provenance.settings.get("estimator", "truncated"),
                    "nees_full_vector_sum": float(np.sum(full_nees)), "nees_full_vector_dof": n_seeds * len(res.estimate.p_hat),
                    "nees_full_vector_band": [float(lo), float(hi)],
                    "in_sample_predictive_chi2_per_row": pred_chi2 / max(pred_rows, 1),
                    "in_sample_predictive_chi2_per_dof": pred_chi2 / max(pred_dof, 1.0),
                    "in_sample_predictive_coverage_95": pred_cover / max(pred_rows, 1)})
        fig.update({"retained_min_max": [int(min(kept)), int(max(kept))], "not_converged": failed,
                    "runs_with_fold_directions": fold_runs,
                    "second_start_run_kept": second,
                    "seconds_per_calibration": (time.perf_counter() - t0) / n_seeds})
        if dims:
            lo, hi = stats.chi2.ppf([0.025, 0.975], int(np.sum(dims)))
            fig.update({"nees_sum": float(np.sum(nees)), "nees_band": [float(lo), float(hi)],
                        "nees_dof": int(np.sum(dims)), "nees_noise_only_sum": float(np.sum(nees_noise))})
            # the same over the calibrations that report "converged" (a result whose retained set
            # did not settle says so in its status and its report)
            ok = np.array(stable, bool)
            if ok.any():
                lo, hi = stats.chi2.ppf([0.025, 0.975], int(np.sum(np.array(dims)[ok])))
                fig.update({"nees_converged_sum": float(np.sum(np.array(nees)[ok])),
                            "nees_noise_only_converged_sum": float(np.sum(np.array(nees_noise)[ok])),
                            "nees_converged_band": [float(lo), float(hi)],
                            "nees_converged_dof": int(np.sum(np.array(dims)[ok])),
                            "nees_not_converged": [[int(seed0 + k), round(float(nees[k]), 1), int(dims[k])]
                                                   for k in np.flatnonzero(~ok)]})
        out[label] = fig
    return out


def _held_back_case(name: str, seed: int | None = None):
    """(model, conditions, measurements, settings) of one held-back case; ``seed`` of the noise
    (default: the workflow's own, 5500 for the twin)."""
    if name == "twin":
        sys.path.insert(0, os.path.join(ROOT, "tests"))
        from test_calibration import CHANNELS, twin_truth
        from twin_model import TwinModel, twin_conditions

        model = TwinModel(channels=CHANNELS)
        cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 7))
        meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.01 for c in CHANNELS},
                          seed=5500 if seed is None else seed)
        return model, cond, meas, CalibrationSettings(cd_min=None)
    workflow, stage = {"wind_tunnel": ("wind_tunnel_hub_loads.toml", 0),
                       "localization": ("blade_loads_localization.toml", 1)}[name]
    loaded = load_workflow(os.path.join(ROOT, "workflows", workflow))
    setup = prepare(loaded)
    cond = synthetic_conditions(loaded.conditions, setup.rotor, setup.density)
    channels = list(loaded.stages[stage].channels)
    tmodel, p_true = truth_model(setup.rotor, channels, setup.settings, loaded.truth, setup.nuisance)
    rel = {c: float(loaded.noise.relative[c]) for c in channels}
    meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels,
                      seed=loaded.noise.seed if seed is None else seed)
    model = BemModel(setup.rotor, setup.grid(cond), channels, setup.settings, setup.nuisance)
    return model, cond, meas, setup.calibration


def held_back_mask(n_points: int, split: str = "rows", n_pitch: int = 6) -> np.ndarray:
    """Which of ``n_points`` operating points are held back: ``rows``, every third point in
    file order (on the workflows' grids, pitch the inner loop with ``n_pitch`` settings per
    tip-speed ratio, that is two whole pitch lines); ``interleaved``, the points whose
    tip-speed-ratio and pitch indices sum to 1 modulo 3 (a third of every pitch line and of
    every tip-speed ratio)."""
    k = np.arange(n_points)
    if split == "rows":
        return k % 3 == 1
    if split == "interleaved":
        return (k // n_pitch + k % n_pitch) % 3 == 1
    raise ValueError(f"split: expected 'rows' or 'interleaved', got {split!r}")


def held_back(name: str, sweep=SWEEP, seed: int | None = None, split: str = "rows") -> dict:
    """Held-back χ²/dof of ``sigma_bar = "auto"`` against a sweep of σ̄ (the points of
    :func:`held_back_mask` held back); ``name`` one of ``wind_tunnel``, ``localization``,
    ``twin`` (``interleaved`` only for the workflows' 6-pitch grids). The truncated estimator,
    whatever the default: σ̄ is its setting (the MAP has none, and would score every σ̄ alike)."""
    model, cond, meas, settings = _held_back_case(name, seed)
    settings = dataclasses.replace(settings, estimator="truncated")
    test = held_back_mask(len(cond), split)
    train = Measurements(cond.subset(~test), meas.channels, meas.values[~test], meas.sigma[~test], "train")
    scores, kept = {}, {}
    for sb in ("auto",) + tuple(sweep):
        res = Calibrator(model, train, dataclasses.replace(settings, sigma_bar=sb)).run()
        pred = res.predict(cond.subset(test), model=model)
        scores[sb] = float(np.mean(((meas.values[test] - pred.values) / meas.sigma[test]) ** 2))
        kept[sb] = res.n_retained
    best = min(scores[sb] for sb in sweep)
    best_sb = min(sweep, key=lambda sb: scores[sb])
    fig = {"auto": scores["auto"], "auto_retained": kept["auto"], "best": best, "best_sigma_bar": best_sb,
           "best_retained": kept[best_sb], "ratio": scores["auto"] / best,
           "sweep": {str(sb): [round(scores[sb], 4), kept[sb]] for sb in sweep}}
    print(f"[held back {name}, {split}] auto {scores['auto']:.3f} ({kept['auto']} θ), best {best:.3f} (σ̄ {best_sb}, "
          f"{kept[best_sb]} θ): ratio {fig['ratio']:.3f}", flush=True)
    return fig


def run(n_seeds: int = 30, with_held_back: bool = True, estimator: str | None = None) -> dict:
    out = coverage(n_seeds, **({"estimator": estimator} if estimator else {}))
    if with_held_back:
        out["held_back"] = {name: held_back(name) for name in ("wind_tunnel", "localization", "twin")}
        out["held_back"]["wind_tunnel_interleaved"] = held_back("wind_tunnel", split="interleaved")
    return out


def publish(out: dict, estimator: str, n_seeds: int, command: str) -> str:
    """Write the twins' figures for the documentation (``docs/validation/data/coverage_<estimator>.json``,
    with the date, the commit and the command: :mod:`publish`); the validation page renders them."""
    from publish import publish as write

    keep = ("coverage_lift_mean", "coverage_drag_mean", "nees_full_vector_sum", "nees_full_vector_dof",
            "nees_full_vector_band", "in_sample_predictive_chi2_per_row", "in_sample_predictive_chi2_per_dof",
            "in_sample_predictive_coverage_95", "not_converged", "retained_min_max", "seconds_per_calibration")
    twins = {k: {f: v[f] for f in keep if f in v} for k, v in out.items() if k != "held_back"}
    return write(f"coverage_{estimator}", {"estimator": estimator, "n_seeds": n_seeds, "twins": twins}, command)


if __name__ == "__main__":
    import json

    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    chosen = [a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--estimator=")]
    n = int(args[0]) if args else 30
    result = run(n, "--no-held-back" not in sys.argv, *chosen[-1:])
    publish(result, chosen[-1] if chosen else CalibrationSettings().estimator, n,
            "python benchmarks/bench_coverage.py " + " ".join(sys.argv[1:]))
    print(json.dumps(result, indent=1))
