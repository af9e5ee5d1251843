"""The Calibrator: the MAP estimate under the stated prior, or ML in the identifiable subspace.

MAP (``estimator = "map"``, the default)
----------------------------------------
1. Noise R as below.
2. The maximum a posteriori estimate under the stated prior P (the correction nodes' smooth-field
   prior; each parameter's stated ``prior_std``; flat where none is stated) by bounded Gauss–Newton
   in prior-whitened coordinates (:meth:`Calibrator._fit_map`).
3. At the estimate, the SVD of the prior-whitened sensitivities R^(−½) G̃ L = U S Wᵀ (P = L Lᵀ): the
   directions L w_i are statistically independent, s_i > 1 where the data determine them better
   than the prior; their eigenshapes and verdicts as below. The Laplace covariance
   L W (I + S²/k)⁻¹ (L W)ᵀ (k the fit scale), plus the field between the nodes through the
   estimate's gain (:mod:`calib.parametrizations.aliasing`).

Truncated ML (``estimator = "truncated"``; Bottasso, Cacciola & Iriarte 2014)
-----------------------------------------------------------------------------
1. Noise R: known (σ from the table or the settings), from repeated records, or
   estimated by iterated ML (R = (1/N) Σ r_k r_kᵀ, diagonal, alternating with step 2-4).
2. Linearize at the current estimate: whitened scaled sensitivities M = R^(−½) G D,
   SVD M = U S Vᵀ, retain θ_i = v_iᵀ p̃ with σ(θ_i) = 1/s_i <= σ̄, or (``sigma_bar =
   "auto"``, the default) the number of θ that minimizes the 10-fold cross-validated
   prediction error over operating points of the linearized problem (:mod:`calib.calibration.truncation`).
3. Estimate the retained θ under bounds (corrections and C_D >= C_D,min at the nodes) by
   constrained Gauss–Newton (:func:`calib.calibration.gauss_newton.estimate_ml`); the others stay at 0.
4. Re-linearize at the estimate and redo the SVD; stop when the retained set is stable
   (same count, principal-angle cosines >= ``stability_cosine``). With ``second_start``
   (default), ``sigma_bar = "auto"`` and a stated noise, a fit whose χ² rejects that noise is started
   again from the prior limit's count, and the better-predicting of the two is kept
   (``Calibrator._second_start``).
5. Covariance of the estimate including the frozen directions: Cov(p̃̂) = V_ID S_ID⁻² V_IDᵀ
   + V_NID (V_NIDᵀ P V_NID) V_NIDᵀ with the prior P (prior σ² per parameter; neighbouring
   correction nodes correlated, ``prior_correlation``)
   (:func:`calib.calibration.identifiability.frozen_aware_covariance`), plus, for the retained θ, the
   aliasing of the field between the nodes (:mod:`calib.parametrizations.aliasing`), the fit
   scale (``scale_by_fit``) and the frozen part's bias through the model's curvature
   (:func:`calib.calibration.identifiability.frozen_curvature_covariance`); confidence bands on the corrected
   polars; confounding of the non-field parameters with the field; a verdict per parameter
   from posterior vs prior; goodness of fit (χ² before over N, after over N − n_retained,
   p-value, per channel, worst points).

Every model call reports a per-point status; failed points are left out of the cost and
counted in the result.
"""

from __future__ import annotations

import difflib
import logging
import time
from typing import Callable

import numpy as np
from scipy import stats

from calib.calibration.gauss_newton import EstimationStatus, StopRule, estimate_map, estimate_ml
from calib.calibration.identifiability import SvdAnalysis, observability, subspace_cosines, svd_analysis
from calib.calibration.map_agreement import map_ml_agreement
from calib.calibration.noise import initial_sigma
from calib.calibration.problem import LeastSquaresProblem
from calib.calibration.result import CalibrationResult
from calib.calibration.result_assembly import assemble_result
from calib.calibration.settings import CalibrationSettings
from calib.calibration.truncation import AutoTruncation, keep_second_start
from calib.calibration.uncertainty import (laplace_covariance, map_fit_scale, map_gain, prior_whitened_svd,
                                           truncated_covariance)
from calib.calibration.uncertainty_terms import ModelTerms
from calib.checks.prior_check import psd_sqrt
from calib.errors import InputError
from calib.measurements import Measurements, check_channels, ml_noise
from calib.types import nominal_vector

log = logging.getLogger(__name__)

__all__ = ["Calibrator", "calibrate"]

FLAT_PRIOR = 1e3
"""Prior 1-σ [scale units] the MAP estimator gives a parameter without a stated prior (no
``Parameter.prior_std``, not in ``prior_std``, not a correction node): flat for any data that
determine it to better than a thousand scales, so such a parameter is estimated by maximum
likelihood, and one the data cannot determine shows its σ unbounded instead of a prior nobody stated."""
NOISE_SETTLED = 1e-3
"""Largest relative change of a channel's σ between two fits below which an estimated noise has settled [-]."""
MAP_DECREASE = 5e-4
"""Cost decrease [-] (half a χ²) below which the MAP iteration stops: the last step was then about
√(2 × 5e-4) = 0.03 posterior standard deviations long (:class:`calib.calibration.gauss_newton.StopRule`). On the
wind-tunnel coverage twin (c) (seed 5003) the Gauss–Newton converges linearly near the bounds: stopping
at a relative decrease of 1e-9 the calibration made 15 model Jacobians in all, with this rule 9."""
SECOND_START_P = 0.01
"""χ² p-value of the first fit below which ``second_start`` runs (see ``Calibrator._second_start``)."""

def _progress_printer(rec: dict) -> None:
    keys = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in rec.items()
                    if k not in ("stage", "qp"))
    print(f"[calib {rec.get('stage', '')}] {keys}", flush=True)


class Calibrator:
    """Calibrate a ForwardModel from measurements (see the module docstring).

    Parameters
    ----------
    model : ForwardModel
    measurements : Measurements
        Channels must be outputs of ``model``.
    settings : CalibrationSettings, optional
    callback : callable(dict), optional
        Called with a progress record after every iteration (``stage`` says which loop);
        with ``settings.verbose`` a line is also printed.
    name : str
        Name of the run (reports, files).
    start : ndarray, optional
        The optimizer's first iterate [parameter units] (default: the nominal values). The
        nominal values stay the reference of the scaled coordinates and of the prior; a start
        away from them serves fits whose derivative vanishes at nominal (a candidate effect at
        zero magnitude). Clipped into the bounds.
    """

    def __init__(self, model, measurements: Measurements, settings: CalibrationSettings | None = None,
                 callback: Callable[[dict], None] | None = None, name: str = "calibration",
                 start: np.ndarray | None = None):
        self.model = model
        self.measurements = measurements
        self.settings = (settings or CalibrationSettings()).validate()
        self.name = name
        self._callbacks = [c for c in (callback, _progress_printer if self.settings.verbose else None) if c]
        self.parameters = tuple(model.parameters)
        model_channels = [c.name for c in model.channels]
        check_channels(measurements, model_channels)
        self.channel_index = [model_channels.index(c) for c in measurements.channels]
        self.channel_units = [model.channels[i].unit for i in self.channel_index]
        self.p0 = nominal_vector(self.parameters)
        self.scale = np.array([q.scale for q in self.parameters], float)
        if np.any(~(self.scale > 0)):
            j = int(np.flatnonzero(~(self.scale > 0))[0])
            raise InputError(f"parameter scale must be > 0, got {self.scale[j]!r}", "model.parameters",
                             field=self.parameters[j].name)
        self.field = model.correction_field() if model.capabilities.correction_field else None
        self.lower, self.upper = self._effective_bounds()
        self.start = None
        if start is not None:
            start = np.asarray(start, float)
            if start.shape != self.p0.shape or not np.all(np.isfinite(start)):
                raise InputError(f"must be {self.p0.size} finite values, got shape {start.shape}", "Calibrator",
                                 field="start")
            self.start = np.clip(start, self.lower, self.upper)
        stated = dict(self.settings.prior_std or {})
        names = [q.name for q in self.parameters]
        for name in stated:
            if name not in names:
                close = difflib.get_close_matches(name, names, 1)
                raise InputError(f"no parameter {name!r} in this model" + (f"; did you mean {close[0]!r}?" if close
                                                                            else f"; parameters: {', '.join(names)}"),
                                 "settings", field=f"calibration.prior_std.{name}")
        self.prior_std = np.array([stated[q.name] if q.name in stated else q.prior_std if np.isfinite(q.prior_std)
                                   else self.settings.prior_sigma * q.scale for q in self.parameters], float)
        # a prior someone stated: the correction nodes' smooth-field prior, a parameter's own, the settings'
        self.prior_stated = np.array([q.name in stated or bool(np.isfinite(q.prior_std)) for q in self.parameters])
        if self.field is not None:
            lay = self.field.layout
            for idx in (lay.lift_index, lay.drag_index):
                self.prior_stated[idx[idx >= 0]] = True
        self.history: list[dict] = []
        st = self.settings
        self.truncation = AutoTruncation(st.cv_folds, st.max_retained, st.cv_one_se)
        self._second_start_record: dict = {}
        self.terms = ModelTerms(model, self.field, st, measurements, self.parameters, self.channel_index,
                                self.prior_std, self.scale, self.lower, self.upper)

    # ------------------------------------------------------------------ setup
    def _effective_bounds(self):
        lower = np.array([q.lower for q in self.parameters], float)
        upper = np.array([q.upper for q in self.parameters], float)
        if self.field is not None:
            lower = self.field.lower_bounds(lower, self.p0, self.settings.cd_min)
        return lower, upper

    def _emit(self, rec: dict) -> None:
        self.history.append(rec)
        for cb in self._callbacks:
            cb(rec)

    # ------------------------------------------------------------------ run
    def run(self) -> CalibrationResult:
        """Calibrate; returns a :class:`CalibrationResult`."""
        t0 = time.perf_counter()
        st = self.settings
        m = self.measurements
        sigma = initial_sigma(self.measurements, self.settings)
        problem = LeastSquaresProblem(self.model, m.conditions, m.values,
                                      sigma if sigma is not None else np.ones_like(m.values),
                                      self.channel_index, self.p0, self.scale, self.lower, self.upper)
        nominal = problem.evaluate(self.p0)
        if nominal.n_failed == len(m.conditions):
            from calib.errors import ModelError

            raise ModelError(f"the nominal model fails at every point: {nominal.evaluation.failure_summary()}")
        if sigma is None:  # ML noise: start from the nominal residual
            resid = m.values - nominal.evaluation.values[:, self.channel_index]
            sigma = np.broadcast_to(ml_noise(resid, nominal.ok), m.values.shape).copy()
            problem = problem.with_sigma(sigma)
        noise_iters = st.max_noise_iterations if st.noise in ("ml", "relative_ml") else 1
        p = self.p0.copy() if self.start is None else self.start.copy()
        for k_noise in range(noise_iters):
            p, svd, lin, status, message = self._fit(problem, p)
            if st.noise not in ("ml", "relative_ml"):
                break
            if st.noise == "relative_ml":
                # one ML factor on the stated σ of every channel, with N − k degrees of freedom
                from calib.calibration.noise import ml_scale
                n_res = int(lin.ok.sum()) * len(self.channel_index)
                fitted = float(np.sum(svd.singular_values ** 2 / (1.0 + svd.singular_values ** 2))) \
                    if st.estimator == "map" else svd.n_retained     # the MAP's effective number of parameters
                k_hat = ml_scale(float(np.sum(lin.residual[lin.ok] ** 2)), n_res, fitted)
                new_sigma = problem.sigma * k_hat
            else:
                resid = m.values - lin.evaluation.values[:, self.channel_index]
                new_sigma = np.broadcast_to(ml_noise(resid, lin.ok), m.values.shape).copy()
            change = float(np.max(np.abs(new_sigma[0] / problem.sigma[0] - 1.0)))
            self._emit({"stage": "noise", "iteration": k_noise + 1, "sigma": new_sigma[0].tolist(),
                        "change": change})
            problem = problem.with_sigma(new_sigma)
            if change < NOISE_SETTLED:
                break
        if st.noise in ("ml", "relative_ml"):
            # the estimator's message is the last fit's: say how many fits the noise estimate took
            settled = change < NOISE_SETTLED
            message = (f"{message}; noise σ estimated over {k_noise + 1} fit(s), "
                       + (f"settled (last change {change:.2g} < {NOISE_SETTLED:g})" if settled else
                          f"NOT settled after max_noise_iterations = {noise_iters} (last change {change:.2g}, "
                          f"settled below {NOISE_SETTLED:g}): σ and the covariance are those of the last fit"))
        lin = problem.linearize(p)
        if st.estimator == "map":
            res = self._finish_map(problem, nominal, lin, status, message)
        else:
            res = self._finish(problem, nominal, lin, self._svd(problem, lin), status, message)
        res.provenance.wall_time = time.perf_counter() - t0    # once the result is whole, its terms included
        return res

    def _svd(self, problem: LeastSquaresProblem, lin) -> SvdAnalysis:
        """SVD at a linearization and the retained set (threshold, all, or chosen by the data)."""
        st = self.settings
        if st.retain == "all":
            return svd_analysis(lin.M, np.inf, st.max_retained)
        if st.sigma_bar != "auto":
            return svd_analysis(lin.M, float(st.sigma_bar), st.max_retained)
        pseudo = lin.residual.reshape(-1) + lin.M @ problem.scaled(lin.p)
        chosen = self.truncation.choose(lin.M, pseudo, len(self.channel_index), lin.ok, self._prior_cov_scaled())
        svd = svd_analysis(lin.M, np.inf)
        retained = np.zeros_like(svd.retained)
        retained[:chosen] = svd.retained[:chosen]
        return SvdAnalysis(svd.singular_values, svd.V, svd.sigma_theta, self.truncation.curve.sigma_bar, retained)

    def _prior_cov_scaled(self) -> np.ndarray:
        """The stated prior covariance of the scaled parameters [scale units²]
        (:meth:`calib.calibration.uncertainty_terms.ModelTerms.prior_cov_scaled`)."""
        return self.terms.prior_cov_scaled()

    def _map_prior_cov_scaled(self) -> np.ndarray:
        """The prior of the MAP estimator [scale units²]: the stated prior, and ``FLAT_PRIOR`` for
        the parameters without one."""
        P = self._prior_cov_scaled()
        flat = np.flatnonzero(~self.prior_stated)
        P[flat, :], P[:, flat] = 0.0, 0.0
        P[flat, flat] = FLAT_PRIOR ** 2
        return P

    def _fit(self, problem: LeastSquaresProblem, p: np.ndarray):
        """The re-linearization loop from ``p``; the first time with ``sigma_bar = "auto"``,
        followed by :meth:`_second_start` when the fit's χ² rejects the stated noise."""
        st = self.settings
        if st.estimator == "map":
            return self._fit_map(problem, p)
        first = st.sigma_bar == "auto" and st.retain != "all" and self.truncation.frozen is None
        lin0 = problem.linearize(p)
        out = self._relinearize_loop(problem, p, lin0)
        if not (first and st.second_start and st.noise not in ("ml", "relative_ml")) or out[3] == "failed":
            return out
        return self._second_start(problem, p, lin0, out)

    def _second_start(self, problem: LeastSquaresProblem, p0: np.ndarray, lin0, first: tuple):
        """Start the automatic choice again from the prior limit's count when the first fit's χ²
        rejects the stated noise (p < ``SECOND_START_P``), and keep the better of the two.

        The count chosen on the nominal linearization is re-made at each re-linearization, but
        all those linearizations lie near a fit with that many θ, where the linearized criterion
        can understate what a re-linearized fit with more θ achieves: on coverage twin (d), seed
        8319, the loop settled on 7 θ at χ²/dof 9.1 (criterion 10.8), and started from the
        limit's 22 θ it settled on 22 θ at χ²/dof 1.26 (criterion 1.73). Each result is judged
        by its own final curve at its own count; the one with fewer θ is kept unless the other's
        criterion is lower by more than that criterion's standard error (the one-standard-error
        rule of :func:`calib.calibration.truncation.cv_curve` across the two starts). When only one of the
        two ended with a settled retained set (status ``converged``), that one takes the place of
        the one with fewer θ in this rule: on coverage twin (d), tuning seed 8302, both starts
        kept 17 θ, and the first, whose last direction still turned by 53°, had been kept over
        the second, which had settled.
        """
        _, svd1, lin1, _, _ = first
        chi2, dof = self._chi2_dof(lin1, svd1)
        p_value = float(stats.chi2.sf(chi2, dof)) if dof > 0 else 1.0
        if p_value >= SECOND_START_P:
            return first
        policy1 = self.truncation
        self.truncation = policy1.restarted_at_limit()
        self._emit({"stage": "second_start", "chi2": chi2, "dof": dof, "p_value": p_value,
                    "first_n_retained": svd1.n_retained})
        problem.remember(lin0)        # the same first linearization, no model call repeated
        second = self._relinearize_loop(problem, p0.copy(), lin0)
        c1, c2 = policy1.curve, self.truncation.curve
        k1, k2 = svd1.n_retained, second[1].n_retained
        cv1, cv2 = float(c1.cv[k1]), float(c2.cv[k2])
        se1, se2 = float(c1.cv_se[k1]), float(c2.cv_se[k2])
        keep_second = keep_second_start((k1, cv1, se1, first[3]), (k2, cv2, se2, second[3]))
        self._second_start_record = {"first_retained": k1, "first_cv": cv1, "first_cv_se": se1,
                                     "first_p_value": p_value, "first_status": first[3],
                                     "second_retained": k2, "second_cv": cv2, "second_cv_se": se2,
                                     "second_status": second[3], "second_kept": int(keep_second)}
        self._emit({"stage": "second_start_done", **self._second_start_record})
        if keep_second:
            return second
        self.truncation = policy1
        problem.remember(lin1)
        return first

    def _relinearize_loop(self, problem: LeastSquaresProblem, p: np.ndarray, lin=None):
        """Estimate and re-linearize until the retained set is stable; ``lin`` the linearization
        at ``p`` when already computed."""
        st = self.settings
        prev_basis = None
        status, message = "not_stable", ""
        lin = problem.linearize(p) if lin is None else lin
        svd = self._svd(problem, lin)
        last_estimate = None
        worst_cos = None
        # the last pass only checks the re-linearization of the last estimate, so that an
        # estimate whose retained set settled on the last allowed pass is not called unstable
        for k in range(st.max_relinearizations + 1):
            basis = svd.basis
            if prev_basis is not None and prev_basis.shape == basis.shape:
                cos = subspace_cosines(prev_basis, basis)
                worst_cos = float(cos.min()) if cos.size else 1.0
                if cos.size == 0 or cos.min() >= st.stability_cosine:
                    status, message = "converged", f"retained set stable after {k} re-linearization(s)"
                    if last_estimate == "stalled":  # stable only because the estimate did not move
                        status, message = "stalled", (
                            f"the estimator stopped where no step decreased the cost (χ² {2 * lin.cost:.4g}, "
                            f"{svd.n_retained} θ): the estimate, its σ and the bands are those of where it stopped, "
                            "not of a minimum; check the fit, or set an explicit sigma_bar")
                    break
            elif prev_basis is not None:
                worst_cos = None        # the count changed: no angle to compare
            if k == st.max_relinearizations:
                break
            theta0 = basis.T @ problem.scaled(p)
            out = estimate_ml(problem, basis, theta0, st.optimizer, StopRule(st.max_iterations, st.tolerance),
                              callback=self._emit, stage=f"estimate[{k + 1}]")
            self._emit({"stage": "relinearize", "iteration": k + 1, "n_retained": svd.n_retained,
                        "cost": out.cost, "estimate_status": out.status, "n_failed": out.linearization.n_failed})
            if out.status == EstimationStatus.QP_FAILED:
                status, message = "failed", out.message
                p = out.p
                break
            last_estimate = out.status
            p = out.p
            prev_basis = basis
            lin = problem.linearize(p)
            svd = self._svd(problem, lin)
        if status == "not_stable":
            turned = "" if worst_cos is None else (
                f"; between the last two re-linearizations the least aligned retained direction turned by "
                f"{np.degrees(np.arccos(np.clip(worst_cos, -1.0, 1.0))):.0f}° (stable: within "
                f"{np.degrees(np.arccos(st.stability_cosine)):.0f}°)")
            message = (f"retained set not stable after {st.max_relinearizations} re-linearizations{turned}: the "
                       "standard deviations, bands and intervals are those of the last linearization and can be too "
                       "narrow (the model is far from linear over the estimate's uncertainty, e.g. a point near a fold "
                       "of the BEM residual where a root appears or vanishes); check the fit, or set an explicit "
                       "sigma_bar")
        return p, svd, lin, status, message

    def _fit_map(self, problem: LeastSquaresProblem, p: np.ndarray):
        """The maximum a posteriori estimate under the stated prior (``estimator = "map"``).

        min ½‖R^(−½) r(p)‖² + ½ p̃ᵀP⁻¹p̃ under the bounds, by the damped Gauss–Newton of
        :func:`calib.calibration.gauss_newton.estimate_map` in the prior-whitened coordinates u (p̃ = L u,
        P = L Lᵀ), where the prior term is ½‖u‖² (MacKay 1992; Rasmussen & Williams 2006,
        ch. 3, on the Laplace approximation). There is no retained set to settle: the status is
        the estimator's (``converged``, ``max_iterations``, ``stalled``, ``failed``).
        """
        st = self.settings
        L = psd_sqrt(self._map_prior_cov_scaled())
        u0 = np.linalg.lstsq(L, problem.scaled(p), rcond=None)[0]
        out = estimate_map(problem, L, u0, st.optimizer,
                           StopRule(st.max_iterations, st.tolerance, decrease_tolerance=MAP_DECREASE),
                           callback=self._emit, stage="map")
        status = "failed" if out.status == EstimationStatus.QP_FAILED else str(out.status)
        lin = out.linearization
        sv, W, L = self._map_decomposition(lin)
        analysis = laplace_covariance(sv, L @ W).directions
        self._emit({"stage": "map_done", "status": status, "cost": out.cost, "iterations": out.iterations,
                    "data_beat_prior": analysis.n_retained, "n_failed": lin.n_failed})
        return out.p, analysis, lin, status, out.message

    def _map_decomposition(self, lin):
        """The SVD of the prior-whitened sensitivities at ``lin`` (:func:`calib.calibration.uncertainty.prior_whitened_svd`,
        P = L Lᵀ the MAP's prior): s (descending), W and L."""
        L = psd_sqrt(self._map_prior_cov_scaled())
        return (*prior_whitened_svd(lin.M, L), L)

    def _finish_map(self, problem, nominal, lin, status, message) -> CalibrationResult:
        """The result of ``estimator = "map"``: the Laplace covariance at the estimate, widened by
        the fit scale (the noise variance multiplied by max(1, χ²/(N − n_eff)), n_eff = Σ s²/(1+s²)
        the effective number of parameters; MacKay 1992) with a stated noise and ``scale_by_fit``."""
        st = self.settings
        s, W, L = self._map_decomposition(lin)
        LW = L @ W
        fit_scale, n_eff = map_fit_scale(float(np.sum(lin.residual[lin.ok] ** 2)),
                                         int(lin.ok.sum()) * len(self.channel_index), s,
                                         st.scale_by_fit and st.noise not in ("ml", "relative_ml"))
        laplace = laplace_covariance(s, LW, fit_scale)
        svd, cov, cov_weak = laplace.directions, laplace.total, laplace.weak
        ev = lin.evaluation
        alpha_seen, eta_seen = self.field.seen(ev) if self.field is not None else (np.zeros(0), np.zeros(0))
        gain = map_gain(LW, s, lin.M)
        alias, _, alias_note, fine = self.terms.aliasing(problem, lin, svd, alpha_seen, eta_seen, gain=gain)
        cov_alias = np.zeros_like(cov)
        if alias is not None:   # the field between the nodes, taken up by the estimate
            cov, cov_alias = cov + alias, alias
        u_hat = np.linalg.lstsq(L, problem.scaled(lin.p), rcond=None)[0]
        c = np.linalg.norm(LW, axis=0)
        theta_hat = (np.where(c > 0, c, 1.0) * (W.T @ u_hat))[svd.retained]
        prior_var = np.diag(self._map_prior_cov_scaled())
        obs = np.clip(1.0 - np.diag(cov) / np.where(prior_var > 0, prior_var, 1.0), 0.0, 1.0)
        try:
            prior_check = self.terms.prior_check(problem, lin, fine)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a check, not the result
            prior_check = {"failed": f"{type(exc).__name__}: {exc}"}
        multiple_roots = np.asarray(ev.extras.get("multiple_roots", np.zeros(len(ev.status), bool)), bool)
        D = np.outer(self.scale, self.scale)
        self._emit({"stage": "map_covariance", "n_eff": n_eff, "fit_scale": fit_scale})
        agreement = map_ml_agreement(lin.M, lin.residual.reshape(-1), problem.scaled(lin.p),
                                     self._map_prior_cov_scaled(), problem.scaled(self.lower),
                                     problem.scaled(self.upper), [q.name for q in self.parameters], fit_scale)
        self._emit({"stage": "map_agreement", "ok": agreement.ok, "max_z": agreement.max_z,
                    "n_fixed": agreement.n_fixed})
        if not agreement.ok:
            log.warning("%s: %s", self.name, agreement.sentence())
            message = f"{message}; {agreement.sentence()}" if message else agreement.sentence()
        return self._result(problem, nominal, lin, svd, cov * D, cov_weak * D,
                            np.diag(svd.sigma_theta[svd.retained] ** 2), theta_hat, obs, status, message,
                            checks={"MAP and ML": agreement.sentence()},
                            fit_scale=fit_scale, prior_check=prior_check, multiple_roots=multiple_roots,
                            aliasing_note=alias_note, gain=gain if alias is not None else np.zeros((0, 0)),
                            cov_alias=cov_alias * D)

    # ------------------------------------------------------------------ outputs
    def _fit_scale(self, lin, svd) -> float:
        """max(1, χ²/(N − n_retained)) with ``scale_by_fit`` and a stated noise, else 1.

        The χ² that the field between the nodes adds on average (``aliasing_chi2``) is not
        subtracted: measured on the coverage twins (docs/user_guide/calibration.md), subtracting it left the prior-draw
        twin (c) overconfident (NEES 573.8 for 426) where the plain factor gave 444.9."""
        st = self.settings
        if not st.scale_by_fit or st.noise in ("ml", "relative_ml"):
            return 1.0
        chi2, dof = self._chi2_dof(lin, svd)
        return max(1.0, chi2 / dof) if dof > 0 else 1.0

    def _chi2_dof(self, lin, svd) -> tuple[float, int]:
        """χ² of the whitened residuals at the points that converged, and N − n_retained."""
        dof = int(lin.ok.sum()) * len(self.channel_index) - svd.n_retained
        return float(np.sum(lin.residual[lin.ok] ** 2)), dof

    def _finish(self, problem, nominal, lin, svd, status, message) -> CalibrationResult:
        B = svd.basis
        # B holds right singular vectors of M at this linearization, so Bᵀ F B = diag(s²) and
        # Cov(θ̂) = diag(σ(θ)²) exactly, without inverting a possibly ill-conditioned matrix
        cov_theta = np.diag(svd.sigma_theta[svd.retained] ** 2)
        prior_cov = self._prior_cov_scaled()
        ev = lin.evaluation
        alpha_seen, eta_seen = self.field.seen(ev) if self.field is not None else (np.zeros(0), np.zeros(0))
        alias, alias_misfit, alias_note, fine = self.terms.aliasing(problem, lin, svd, alpha_seen, eta_seen)
        try:
            prior_check = self.terms.prior_check(problem, lin, fine)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a check, not the result
            prior_check = {"failed": f"{type(exc).__name__}: {exc}"}
        fit_scale = self._fit_scale(lin, svd)
        cov_theta = cov_theta * fit_scale
        curvature_cov, curvature = self.terms.curvature(problem, lin, svd, prior_cov)
        multiple_roots = np.asarray(ev.extras.get("multiple_roots", np.zeros(len(ev.status), bool)), bool)
        fold = self.terms.fold_directions(lin, svd, multiple_roots)
        parts, sigmas = truncated_covariance(svd.V, svd.sigma_theta, svd.retained, prior_cov, alias, fit_scale,
                                             curvature_cov, [d["theta"] for d in fold])
        fold = [{**d, **sigmas[d["theta"]]} for d in fold]
        D = np.outer(self.scale, self.scale)
        return self._result(problem, nominal, lin, svd, parts.total * D, parts.frozen * D, cov_theta,
                            B.T @ problem.scaled(lin.p), observability(svd.V, svd.retained), status, message,
                            fit_scale=fit_scale, aliasing_chi2=alias_misfit, aliasing_note=alias_note,
                            curvature=curvature, prior_check=prior_check, multiple_roots=multiple_roots,
                            fold_directions=fold)

    def _result(self, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs, status, message,
                **extra) -> CalibrationResult:
        """The result of either estimator (:func:`calib.calibration.result_assembly.assemble_result`), with the
        history, the automatic truncation's record and the run's name."""
        st = self.settings
        curve = self.truncation.curve
        truncation = curve.to_dict() if curve is not None and st.sigma_bar == "auto" and st.retain != "all" else {}
        if truncation and self._second_start_record:
            truncation.update(self._second_start_record)
        # wall time 0 here: run() sets it once the result is whole (the assembly's model calls included)
        return assemble_result(self.terms, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs,
                               status, message, 0.0, history=self.history, truncation=truncation, name=self.name,
                               **extra)


def calibrate(model, measurements: Measurements, **settings) -> CalibrationResult:
    """Shortcut: ``Calibrator(model, measurements, CalibrationSettings(**settings)).run()``."""
    callback = settings.pop("callback", None)
    name = settings.pop("name", "calibration")
    return Calibrator(model, measurements, CalibrationSettings(**settings), callback, name).run()
