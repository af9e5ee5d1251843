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
   prediction error over operating points of the linearized problem (:mod:`calib.truncation`).
3. Estimate the retained θ under bounds (corrections and C_D >= C_D,min at the nodes) by
   constrained Gauss–Newton (:func:`calib.estimation.estimate`); the others stay at 0.
4. Re-linearize at the estimate and redo the SVD; stop when the retained set is stable
   (same count, principal-angle cosines >= ``stability_cosine``). With ``second_start``
   (default), ``sigma_bar = "auto"`` and a stated noise, a fit whose χ² rejects that noise is started
   again from the prior limit's count, and the better-predicting of the two is kept
   (``Calibrator._second_start``).
5. Covariance of the estimate including the frozen directions: Cov(p̃̂) = V_ID S_ID⁻² V_IDᵀ
   + V_NID (V_NIDᵀ P V_NID) V_NIDᵀ with the prior P (prior σ² per parameter; neighbouring
   correction nodes correlated, ``prior_correlation``)
   (:func:`calib.identifiability.frozen_aware_covariance`), plus, for the retained θ, the
   aliasing of the field between the nodes (:mod:`calib.parametrizations.aliasing`), the fit
   scale (``scale_by_fit``) and the frozen part's bias through the model's curvature
   (:func:`calib.identifiability.frozen_curvature_covariance`); confidence bands on the corrected
   polars; confounding of the non-field parameters with the field; a verdict per parameter
   from posterior vs prior; goodness of fit (χ² before over N, after over N − n_retained,
   p-value, per channel, worst points).

Every model call reports a per-point status; failed points are left out of the cost and
counted in the result.
"""

from __future__ import annotations

import difflib
import time
from dataclasses import asdict, replace
from typing import Callable

import numpy as np
from scipy import stats

from calib.calibration_settings import ESTIMATORS, NOISE_MODES, CalibrationSettings
from calib.errors import InputError
from calib.estimation import LeastSquaresProblem, estimate
from calib.identifiability import (SvdAnalysis, confounding, cramer_rao, fisher_matrix, fold_dominated_directions,
                                   frozen_curvature_covariance, observability,
                                   parameter_verdicts, subspace_cosines, svd_analysis)
from calib.measurements import Measurements, check_channels, ml_noise, noise_from_repeats
from calib.parametrizations.aliasing import FineSensitivities
from calib.prior_check import psd_sqrt
from calib.result import CalibrationResult, Estimate, Fit, Identifiability, Provenance, Uncertainty
from calib.truncation import AutoTruncation
from calib.uncertainty import truncated_covariance
from calib.types import nominal_vector

__all__ = ["CalibrationSettings", "Calibrator", "calibrate", "NOISE_MODES", "ESTIMATORS"]

FLAT_PRIOR = 1e3
"""Prior 1-σ [scale units] the MAP estimator gives a parameter without a stated prior (no
``Parameter.prior_std``, not in ``prior_std``, not a correction node): flat for any data that
determine it to better than a thousand scales, so such a parameter is estimated by maximum
likelihood, and one the data cannot determine shows its σ unbounded instead of a prior nobody stated."""
MAP_DECREASE = 5e-4
"""Cost decrease [-] (half a χ²) below which the MAP iteration stops: the last step was then about
√(2 × 5e-4) = 0.03 posterior standard deviations long (:func:`calib.estimation.estimate`). On the
wind-tunnel coverage twin (c) (seed 5003) the Gauss–Newton converges linearly near the bounds: stopping
at a relative decrease of 1e-9 the calibration made 15 model Jacobians in all, with this rule 9."""
SECOND_START_P = 0.01
"""χ² p-value of the first fit below which ``second_start`` runs (see ``Calibrator._second_start``)."""

def _progress_printer(rec: dict) -> None:
    keys = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in rec.items()
                    if k not in ("stage", "qp"))
    print(f"[calib {rec.get('stage', '')}] {keys}", flush=True)


def keep_second_start(first: tuple, second: tuple) -> bool:
    """Whether the automatic choice keeps its second start (:meth:`Calibrator._second_start`).

    Each start is (retained count, criterion at it, its standard error, status). The default
    is the start whose retained set settled (status ``converged``) when only one did, else the
    one with fewer θ, else (equal counts) the first; the other is kept only if its criterion is
    lower than the default's by more than its own standard error. A failed second start, or
    one without a finite criterion, is never kept.
    """
    (k1, cv1, se1, s1), (k2, cv2, se2, s2) = first, second
    if s2 == "failed" or not np.isfinite(cv2):
        return False
    settled1, settled2 = s1 == "converged", s2 == "converged"
    default_second = settled2 if settled1 != settled2 else k2 < k1
    return not cv1 < cv2 - se1 if default_second else cv2 < cv1 - se2


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

    def _initial_sigma(self) -> np.ndarray:
        m = self.measurements
        shape = m.values.shape
        s = self.settings
        if s.noise == "repeats":
            return np.broadcast_to(noise_from_repeats(m), shape).copy()
        if s.noise in ("relative", "relative_ml") or (s.noise == "ml" and s.relative_sigma):
            # ml: the stated model is the start of the iteration (instead of the nominal residual)
            from calib.noise import relative_noise
            return relative_noise(m.values, m.channels, s.relative_sigma, m.source)
        if s.sigma:
            unknown = [c for c in s.sigma if c not in m.channels]
            if unknown:
                raise InputError(f"sigma given for unmeasured channel(s) {', '.join(unknown)}; measured: "
                                 f"{', '.join(m.channels)}", "settings", field="sigma")
            missing = [c for c in m.channels if c not in s.sigma]
            if not missing:
                sig = np.array([float(s.sigma[c]) for c in m.channels])
                if np.any(~(sig > 0)):
                    raise InputError("sigma must be > 0", "settings", field="sigma")
                return np.broadcast_to(sig, shape).copy()
            if m.sigma is None and s.noise == "known":
                raise InputError(f"no sigma for channel(s) {', '.join(missing)}", "settings", field="sigma")
        if m.sigma is not None:
            return m.sigma.copy()
        if s.noise == "known":
            raise InputError(
                "noise = 'known' needs the 1-σ noise of every channel, but the table has no _sigma columns ("
                + ", ".join(f"{c}_sigma" for c in m.channels) + ") and no sigma is set: set [calibration] sigma = {"
                + ", ".join(f"{c} = ..." for c in m.channels) + "} (absolute, SI units: W, N, N m), add the _sigma "
                "columns, or choose [calibration] noise = \"ml\" (from the residuals) or \"repeats\" (from "
                "repeated records); in Python: CalibrationSettings(sigma={...})", m.source, field="calibration.sigma")
        return None  # ml: from the nominal residual

    # ------------------------------------------------------------------ run
    def run(self) -> CalibrationResult:
        """Calibrate; returns a :class:`CalibrationResult`."""
        t0 = time.perf_counter()
        st = self.settings
        m = self.measurements
        sigma = self._initial_sigma()
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
                from calib.noise import ml_scale
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
            if change < 1e-3:
                break
        lin = problem.linearize(p)
        if st.estimator == "map":
            return self._finish_map(problem, nominal, lin, status, message, time.perf_counter() - t0)
        svd = self._svd(problem, lin)
        return self._finish(problem, nominal, lin, svd, status, message, time.perf_counter() - t0)

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
        """The stated prior covariance of the scaled parameters [scale units²]: ``prior_std``
        per parameter, neighbouring field nodes correlated by the smooth-field prior."""
        prior_scaled = self.prior_std / self.scale
        prior_cov = np.outer(prior_scaled, prior_scaled)
        if self.field is not None:
            prior_cov = prior_cov * self.field.node_correlation(self.settings.prior_correlation)
        return prior_cov

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
        rule of :func:`calib.truncation.cv_curve` across the two starts). When only one of the
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
            out = estimate(problem, basis, theta0, st.optimizer, st.max_iterations, st.tolerance,
                           callback=self._emit, stage=f"estimate[{k + 1}]")
            self._emit({"stage": "relinearize", "iteration": k + 1, "n_retained": svd.n_retained,
                        "cost": out.cost, "estimate_status": out.status, "n_failed": out.linearization.n_failed})
            if out.status in ("qp_failed",):
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
        :func:`calib.estimation.estimate` in the prior-whitened coordinates u (p̃ = L u,
        P = L Lᵀ), where the prior term is ½‖u‖² (MacKay 1992; Rasmussen & Williams 2006,
        ch. 3, on the Laplace approximation). There is no retained set to settle: the status is
        the estimator's (``converged``, ``max_iterations``, ``stalled``, ``failed``).
        """
        st = self.settings
        L = psd_sqrt(self._map_prior_cov_scaled())
        u0 = np.linalg.lstsq(L, problem.scaled(p), rcond=None)[0]
        out = estimate(problem, L, u0, st.optimizer, st.max_iterations, st.tolerance, callback=self._emit,
                       stage="map", prior=True, decrease_tolerance=MAP_DECREASE)
        status = {"qp_failed": "failed"}.get(out.status, out.status)
        lin = out.linearization
        sv, W, L = self._map_decomposition(lin)
        analysis = self._map_analysis(sv, L @ W)[0]
        self._emit({"stage": "map_done", "status": status, "cost": out.cost, "iterations": out.iterations,
                    "data_beat_prior": analysis.n_retained, "n_failed": lin.n_failed})
        return out.p, analysis, lin, status, out.message

    def _map_decomposition(self, lin):
        """The SVD of the prior-whitened sensitivities A = R^(−½) G̃ L = U S Wᵀ at ``lin`` (P = L Lᵀ
        the MAP's prior): s (descending), W and L."""
        L = psd_sqrt(self._map_prior_cov_scaled())
        A = lin.M @ L
        lam, W = np.linalg.eigh(A.T @ A)
        order = np.argsort(lam)[::-1]
        return np.sqrt(np.clip(lam[order], 0.0, None)), W[:, order], L

    @staticmethod
    def _map_analysis(s, LW, fit_scale: float = 1.0):
        """The Laplace covariance of the scaled parameters from :meth:`_map_decomposition`,
        (G̃ᵀR⁻¹G̃/k + P⁻¹)⁻¹ = L W (I + S²/k)⁻¹ (L W)ᵀ with k = ``fit_scale``.

        Returns the analysis in the result's terms (directions p̃ ∝ L w_i as unit columns of V,
        s_i, σ of each direction's coordinate [scale units], "retained" = s_i > 1: the data
        determine that direction better than the prior), the covariance [scale units²] and
        its part along the directions where the prior dominates (s_i ≤ 1).
        """
        shrink = 1.0 / (1.0 + s ** 2 / fit_scale)
        cov = (LW * shrink) @ LW.T
        weak = s <= 1.0
        cov_weak = (LW[:, weak] * shrink[weak]) @ LW[:, weak].T
        c = np.linalg.norm(LW, axis=0)
        c = np.where(c > 0, c, 1.0)
        return SvdAnalysis(s, LW / c, c * np.sqrt(shrink), 1.0, ~weak), cov, cov_weak

    def _finish_map(self, problem, nominal, lin, status, message, wall) -> CalibrationResult:
        """The result of ``estimator = "map"``: the Laplace covariance at the estimate, widened by
        the fit scale (the noise variance multiplied by max(1, χ²/(N − n_eff)), n_eff = Σ s²/(1+s²)
        the effective number of parameters; MacKay 1992) with a stated noise and ``scale_by_fit``."""
        st = self.settings
        n_rows = int(lin.ok.sum()) * len(self.channel_index)
        s, W, L = self._map_decomposition(lin)
        LW = L @ W
        n_eff = float(np.sum(s ** 2 / (1.0 + s ** 2)))
        chi2 = float(np.sum(lin.residual[lin.ok] ** 2))
        fit_scale = 1.0
        if st.scale_by_fit and st.noise not in ("ml", "relative_ml") and n_rows > n_eff:
            fit_scale = max(1.0, chi2 / (n_rows - n_eff))
        svd, cov, cov_weak = self._map_analysis(s, LW, fit_scale)
        ev = lin.evaluation
        alpha_seen, eta_seen = self.field.seen(ev) if self.field is not None else (np.zeros(0), np.zeros(0))
        gain = (LW / (1.0 + s ** 2)) @ (lin.M @ LW).T    # p̃̂ = gain r̃: L (AᵀA + I)⁻¹ Aᵀ
        alias, _, alias_note, fine = self._aliasing(problem, lin, svd, alpha_seen, eta_seen, gain=gain)
        cov_alias = np.zeros_like(cov)
        if alias is not None:   # the field between the nodes, taken up by the estimate
            cov, cov_alias = cov + alias, alias
        u_hat = np.linalg.lstsq(L, problem.scaled(lin.p), rcond=None)[0]
        c = np.linalg.norm(LW, axis=0)
        theta_hat = (np.where(c > 0, c, 1.0) * (W.T @ u_hat))[svd.retained]
        prior_var = np.diag(self._map_prior_cov_scaled())
        obs = np.clip(1.0 - np.diag(cov) / np.where(prior_var > 0, prior_var, 1.0), 0.0, 1.0)
        try:
            prior_check = self._prior_check(problem, lin, fine)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a check, not the result
            prior_check = {"failed": f"{type(exc).__name__}: {exc}"}
        multiple_roots = np.asarray(ev.extras.get("multiple_roots", np.zeros(len(ev.status), bool)), bool)
        D = np.outer(self.scale, self.scale)
        self._emit({"stage": "map_covariance", "n_eff": n_eff, "fit_scale": fit_scale})
        return self._result(problem, nominal, lin, svd, cov * D, cov_weak * D,
                            np.diag(svd.sigma_theta[svd.retained] ** 2), theta_hat, obs, status, message, wall,
                            fit_scale=fit_scale, prior_check=prior_check, multiple_roots=multiple_roots,
                            aliasing_note=alias_note, gain=gain if alias is not None else np.zeros((0, 0)),
                            cov_alias=cov_alias * D)

    # ------------------------------------------------------------------ outputs
    def _aliasing(self, problem, lin, svd, alpha_seen, eta_seen, gain: np.ndarray | None = None
                  ) -> tuple[np.ndarray | None, float, str, FineSensitivities | None]:
        """Cov of the retained θ from the field between the nodes (scale units²), the χ² it adds
        to the residuals on average, why it is left out ('' when it is in, or when there is
        no correction field or nothing for it to act on; :mod:`calib.parametrizations.aliasing`),
        and the fine-grid sensitivities it used (None when left out). With ``gain`` (the MAP
        estimate's linear response to the whitened data, p̃ per row [scale units]) the covariance is
        that of the whole scaled vector, gain W Σ_δ Wᵀ gainᵀ, and the χ² is not computed (0)."""
        st = self.settings
        if self.field is None or self.field.grid is None or not svd.retained.any() or not alpha_seen.size:
            return None, 0.0, "", None
        left_out = ("the bands leave out how a field varying between the correction nodes biases the retained θ, "
                    "so they can be too narrow for polars that vary between the nodes")
        if not st.representation_error:
            return None, 0.0, f"representation_error = false: {left_out}.", None
        if st.prior_correlation <= 0:
            return None, 0.0, (f"prior_correlation = 0 (independent nodes) defines no field between the nodes to "
                               f"propagate: {left_out}; the field's variance at each reached point is in the "
                               f"bands."), None
        if not self.model.capabilities.refinable:
            return None, 0.0, (f"the model ({self.model.capabilities.name}) cannot be rebuilt on a finer correction "
                               f"grid (no with_grid, e.g. an FMU): {left_out}."), None
        lay = self.field.layout
        if (lay.lift_index < 0).any() or (lay.drag_index < 0).any():
            return None, 0.0, f"the correction field does not carry both lift and drag at every node: {left_out}.", None
        from calib.parametrizations.aliasing import aliasing_covariance, fine_sensitivities

        r = svd.retained
        fine = fine_sensitivities(self.model, lin.p, problem.conditions, problem.sigma, problem.channel_index,
                                  lin.ok, alpha_seen, eta_seen)
        if gain is not None:
            from calib.parametrizations.aliasing import discrepancy_propagated

            return (discrepancy_propagated(gain @ fine.W, self.field, fine, self.prior_std, st.prior_correlation),
                    0.0, "", fine)
        cov, chi2 = aliasing_covariance(self.model, lin.p, problem.conditions, problem.sigma, problem.channel_index,
                                        lin.ok, lin.M, svd.V[:, r], 1.0 / svd.sigma_theta[r], self.prior_std,
                                        st.prior_correlation, alpha_seen, eta_seen, sensitivities=fine)
        return cov, chi2, "", fine

    def _prior_check(self, problem, lin, fine) -> dict:
        """The data's estimate of the correction field's prior amplitude (:mod:`calib.prior_check`),
        linearized at the MAP under the stated prior (:func:`calib.prior_check.map_point`, from the
        estimate): on the fine grid of the aliasing term when it was computed (``fine`` given),
        else on the calibration nodes; {} without a correction field or with ``prior_check`` off."""
        if self.field is None or self.field.grid is None or not self.settings.prior_check:
            return {}
        from calib.parametrizations.aliasing import fine_sensitivities, grid_correlation_sqrt
        from calib.prior_check import map_point, prior_amplitude

        n_ch = len(self.channel_index)
        P = self._prior_cov_scaled()

        last = {}

        def linearize_at(x):
            p = problem.unscaled(x, clip=True)
            last["at"] = at = problem.linearize(p)
            return problem.scaled(p), at.residual.reshape(-1), np.repeat(at.ok, n_ch), at.M

        def evaluate_at(x):
            p = problem.unscaled(x, clip=True)
            out = problem.evaluate(p)
            return problem.scaled(p), out.residual.reshape(-1), np.repeat(out.ok, n_ch)

        failed_before = problem.n_failed_points_total   # the check's own evaluations are not the fit's failures
        # the MAP estimator's result is the MAP point of the stated prior already (up to its flat priors)
        mp = map_point(linearize_at, problem.scaled(lin.p), P, evaluate_at=evaluate_at,
                       max_iterations=0 if self.settings.estimator == "map" else 10)
        problem.n_failed_points_total = failed_before
        lay = self.field.layout
        blocks = [idx[idx >= 0] for idx in (lay.lift_index.ravel(), lay.drag_index.ravel())]
        field_cols = np.concatenate(blocks)
        other = np.setdiff1d(np.arange(len(self.parameters)), field_cols)
        rows = mp.ok_rows
        M = mp.M[rows]
        z = mp.residual[rows] + M @ mp.x
        if fine is not None:
            at_map = last["at"]                 # map_point ends on the point it linearized last
            if np.max(np.abs(at_map.p - lin.p) / self.scale) > 1e-9:   # (the MAP estimator's is that point)
                fine = fine_sensitivities(self.model, at_map.p, problem.conditions, problem.sigma,
                                          problem.channel_index, at_map.ok, *self.field.seen(at_map.evaluation))
            L = grid_correlation_sqrt(fine.fine, self.field.correlation_lengths(self.settings.prior_correlation))
            sd = [float(np.sqrt(np.mean(self.prior_std[b] ** 2))) for b in blocks]
            Z_f, K_f = fine.W[rows], None
            L_f = np.block([[sd[0] * L, np.zeros_like(L)], [np.zeros_like(L), sd[1] * L]])
        else:
            Z_f, K_f, L_f = M[:, field_cols], P[np.ix_(field_cols, field_cols)], None
        check = prior_amplitude(z, Z_f, K_f, M[:, other], P[np.ix_(other, other)], between_nodes=fine is not None,
                                field_sqrt=L_f)
        check = replace(check, chi2_map=mp.chi2, chi2_estimate=float(np.sum(lin.residual[lin.ok] ** 2)),
                         map_iterations=mp.iterations,
                         map_converged=True if self.settings.estimator == "map" else mp.converged)
        return check.to_dict()

    def _curvature(self, problem, lin, svd, prior_cov) -> tuple[np.ndarray | None, dict]:
        """The retained θ's covariance from the frozen directions' prior through the model's
        curvature (:func:`calib.identifiability.frozen_curvature_covariance`) [scale units²],
        and what it adds relative to the noise part (``result.curvature``); (None, {}) when
        there is nothing to propagate, (None, {"samples": 0}) when the term is switched off."""
        st = self.settings
        r = svd.retained
        if not r.any() or r.all():
            return None, {}
        if st.curvature_samples == 0:
            return None, {"samples": 0}
        n_ch = len(self.channel_index)

        def residual_at(step):
            p = np.clip(lin.p + self.scale * step, self.lower, self.upper)
            out = problem.evaluate(p)
            return out.residual.reshape(-1), np.repeat(out.ok, n_ch), (p - lin.p) / self.scale

        failed_before = problem.n_failed_points_total   # prior draws are not the fit's failures
        cov, info = frozen_curvature_covariance(residual_at, lin.residual.reshape(-1), np.repeat(lin.ok, n_ch),
                                                lin.M, svd.V, svd.sigma_theta, r, prior_cov, st.curvature_samples)
        problem.n_failed_points_total = failed_before
        # its size against the noise part, per retained θ: tr(S² C)/k and the largest ratio
        ratio = np.diag(cov) / svd.sigma_theta[r] ** 2
        return cov, {**info, "variance_ratio_mean": float(np.mean(ratio)), "variance_ratio_max": float(np.max(ratio))}

    def _fold_directions(self, lin, svd, multiple_roots) -> list:
        """Retained directions that points with several roots of the BEM equations determine
        (:func:`calib.identifiability.fold_dominated_directions`): one record per (point, direction);
        their stated covariance gets the prior variance along them added (:func:`calib.uncertainty.fold_inflation`),
        so their σ is at least the prior's."""
        Vr = svd.V[:, svd.retained]
        return fold_dominated_directions(lin.M, len(self.channel_index), Vr, svd.singular_values[svd.retained],
                                         multiple_roots, lin.ok)

    def _tightening(self, problem, lin, cov_p, radius) -> dict:
        """Which measurements would tighten the σ of each parameter that is not a correction node
        (:mod:`calib.tightening`); {} without such parameters, without a rotor radius, or for a model
        whose every probe is a simulation (one that cannot be refined, e.g. an FMU)."""
        field_cols = set()
        if self.field is not None:
            lay = self.field.layout
            field_cols = {int(j) for idx in (lay.lift_index, lay.drag_index) for j in idx[idx >= 0].ravel()}
        names = [q.name for j, q in enumerate(self.parameters) if j not in field_cols]
        if not self.settings.tightening or not names or radius is None \
                or not self.model.capabilities.refinable:
            return {}
        from calib.tightening import tightening

        m = self.measurements
        y = np.abs(lin.evaluation.values[:, self.channel_index])
        rel = {c: float(np.median((problem.sigma[:, i] / np.maximum(y[:, i], 1e-300))[lin.ok]))
               for i, c in enumerate(m.channels) if lin.ok.any()}
        field_variance = None
        st = self.settings
        if self.field is not None and self.field.grid is not None and st.representation_error \
                and st.prior_correlation > 0:
            from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities

            a_cal, e_cal = self.field.seen(lin.evaluation)

            def field_variance(cond, cols, ev):
                a, e = self.field.seen(ev)
                fs = fine_sensitivities(self.model, lin.p, cond, np.ones((len(cond), len(cols))), cols, ev.ok,
                                        np.concatenate([a, a_cal]), np.concatenate([e, e_cal]))
                var = discrepancy_propagated(fs.W, self.field, fs, self.prior_std, st.prior_correlation, diagonal=True)
                return var.reshape(len(cond), len(cols))
        try:
            return tightening(self.model, lin.p, cov_p / np.outer(self.scale, self.scale), self.scale, m.conditions,
                              radius, list(m.channels), rel, names, field_variance=field_variance)
        except (InputError, np.linalg.LinAlgError, ValueError) as exc:     # advice, not the result
            return {"failed": f"{type(exc).__name__}: {exc}"}

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

    def _finish(self, problem, nominal, lin, svd, status, message, wall) -> CalibrationResult:
        B = svd.basis
        # B holds right singular vectors of M at this linearization, so Bᵀ F B = diag(s²) and
        # Cov(θ̂) = diag(σ(θ)²) exactly, without inverting a possibly ill-conditioned matrix
        cov_theta = np.diag(svd.sigma_theta[svd.retained] ** 2)
        prior_cov = self._prior_cov_scaled()
        ev = lin.evaluation
        alpha_seen, eta_seen = self.field.seen(ev) if self.field is not None else (np.zeros(0), np.zeros(0))
        alias, alias_misfit, alias_note, fine = self._aliasing(problem, lin, svd, alpha_seen, eta_seen)
        try:
            prior_check = self._prior_check(problem, lin, fine)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a check, not the result
            prior_check = {"failed": f"{type(exc).__name__}: {exc}"}
        fit_scale = self._fit_scale(lin, svd)
        cov_theta = cov_theta * fit_scale
        curvature_cov, curvature = self._curvature(problem, lin, svd, prior_cov)
        multiple_roots = np.asarray(ev.extras.get("multiple_roots", np.zeros(len(ev.status), bool)), bool)
        fold = self._fold_directions(lin, svd, multiple_roots)
        parts, sigmas = truncated_covariance(svd.V, svd.sigma_theta, svd.retained, prior_cov, alias, fit_scale,
                                             curvature_cov, [d["theta"] for d in fold])
        fold = [{**d, **sigmas[d["theta"]]} for d in fold]
        D = np.outer(self.scale, self.scale)
        return self._result(problem, nominal, lin, svd, parts.total * D, parts.frozen * D, cov_theta,
                            B.T @ problem.scaled(lin.p), observability(svd.V, svd.retained), status, message, wall,
                            fit_scale=fit_scale, aliasing_chi2=alias_misfit, aliasing_note=alias_note,
                            curvature=curvature, prior_check=prior_check, multiple_roots=multiple_roots,
                            fold_directions=fold)

    def _result(self, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs, status, message,
                wall, **extra) -> CalibrationResult:
        """The :class:`CalibrationResult` of either estimator from its covariance [parameter units²]
        and its directions; ``extra`` are the estimator's own fields of the result's parts."""
        m = self.measurements
        radius, spec = self._model_record()
        fit = self._fit_part(problem, nominal, lin)     # the failures counted before the tightening's probes
        extra.setdefault("tightening", self._tightening(problem, lin, cov_p, radius))
        res = CalibrationResult(
            parameters=[asdict(q) for q in self.parameters], channels=list(m.channels),
            channel_units=self.channel_units, conditions=m.conditions.as_dict(),
            estimate=Estimate(self.p0, lin.p, self.lower, self.upper, self.scale, theta_hat, status, message,
                              self.history),
            identifiability=self._identifiability(lin, svd, cov_p, obs),
            uncertainty=Uncertainty(cov_p, np.sqrt(np.maximum(np.diag(cov_p), 0.0)), cov_theta, self.prior_std,
                                    cov_frozen),
            fit=fit,
            provenance=Provenance(self._settings_record(), spec, radius, wall_time=wall,
                                  inputs={m.source: m.sha256} if m.sha256 else {}),
            name=self.name).replace(**extra)
        st = self.settings
        if self.field is not None and self.field.grid is not None:
            res.uncertainty.polar_bands = self.field.bands(
                lin.p, cov_p, cov_frozen, eta=st.band_eta, confidence=st.band_confidence,
                prior_std=self.prior_std if st.representation_error else None,
                correlation_length=st.prior_correlation, cd_min=st.cd_min)
        return res

    def _identifiability(self, lin, svd, cov_p, obs) -> Identifiability:
        """The result's identifiability part: the directions, the Cramér–Rao figures, the verdicts
        and the truncation curve (empty for an explicit σ̄ or with every parameter kept)."""
        st = self.settings
        F = fisher_matrix(lin.M)
        _, crb_std_scaled, corr = cramer_rao(F)
        conf = confounding(F, self.prior_std / self.scale, self.parameters)
        std_p = np.sqrt(np.maximum(np.diag(cov_p), 0.0))
        verdicts = parameter_verdicts(self.parameters, lin.p, self.lower, self.upper, std_p, self.prior_std, obs,
                                      conf, st.identified_ratio, st.confounded_share)
        curve = self.truncation.curve
        truncation = curve.to_dict() if curve is not None and st.sigma_bar == "auto" and st.retain != "all" else {}
        if truncation and self._second_start_record:
            truncation.update(self._second_start_record)
        return Identifiability(svd.singular_values, svd.V, svd.sigma_theta, svd.retained, float(svd.sigma_bar),
                               corr, crb_std_scaled * self.scale, obs, verdicts, conf, truncation)

    def _fit_part(self, problem, nominal, lin) -> Fit:
        """The result's fit part: the model before and after against the measurements, χ², failures."""
        m = self.measurements
        before = nominal.evaluation.values[:, self.channel_index]
        ev = lin.evaluation
        alpha_seen, eta_seen = self.field.seen(ev) if self.field is not None else (np.zeros(0), np.zeros(0))
        failures = {"nominal": nominal.n_failed, "final": lin.n_failed,
                    "total_failed_point_evaluations": problem.n_failed_points_total,
                    "model_evaluations": problem.n_evaluations, "model_jacobians": problem.n_jacobians}
        return Fit(m.values, problem.sigma, before, ev.values[:, self.channel_index], nominal.evaluation.status,
                   ev.status, problem.sigma[0],
                   float(np.sum(((m.values - before)[nominal.ok] / problem.sigma[nominal.ok]) ** 2)),
                   float(np.sum(lin.residual[lin.ok] ** 2)), alpha_seen, eta_seen, failures=failures)

    def _model_record(self) -> tuple[float | None, dict | None]:
        """The rotor radius [m] and the spec that rebuilds the model, (None, None) when it cannot be rebuilt."""
        if not self.model.capabilities.rebuildable:
            return None, None
        try:
            return self.model.rotor_radius, self.model.spec()
        except InputError:
            return self.model.rotor_radius, None

    def _settings_record(self) -> dict:
        """The settings as the result records them: the model's name and the effective lower bounds added."""
        settings = asdict(self.settings)
        settings["model"] = self.model.capabilities.name
        settings["lower_effective"] = self.lower.tolist()
        return settings


def calibrate(model, measurements: Measurements, **settings) -> CalibrationResult:
    """Shortcut: ``Calibrator(model, measurements, CalibrationSettings(**settings)).run()``."""
    callback = settings.pop("callback", None)
    name = settings.pop("name", "calibration")
    return Calibrator(model, measurements, CalibrationSettings(**settings), callback, name).run()
