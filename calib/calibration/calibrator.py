"""The Calibrator: the MAP estimate under the stated prior, or ML in the identifiable subspace.

MAP (``estimator = "map"``, the default)
----------------------------------------
1. Noise R as below.
2. The maximum a posteriori estimate under the stated prior P (the correction nodes' smooth-field
   prior; each parameter's stated ``prior_std``; flat where none is stated) by bounded Gauss–Newton
   in prior-whitened coordinates (:meth:`calib.calibration.map_fit.MapFit.fit`).
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
   (:meth:`calib.calibration.truncated_fit.TruncatedFit.second_start`).
5. Covariance of the estimate including the frozen directions: Cov(p̃̂) = V_ID S_ID⁻² V_IDᵀ
   + V_NID (V_NIDᵀ P V_NID) V_NIDᵀ with the prior P (prior σ² per parameter; neighbouring
   correction nodes correlated, ``prior_correlation``)
   (:func:`calib.calibration.identifiability.frozen_aware_covariance`), plus, for the retained θ, the
   aliasing of the field between the nodes (:mod:`calib.parametrizations.aliasing`), the fit
   scale (``scale_by_fit``) and the frozen part's bias through the model's curvature
   (:func:`calib.calibration.frozen_curvature.frozen_curvature_covariance`); confidence bands on the corrected
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

from calib.calibration.eiv_joint import fit_errors_in_variables
from calib.calibration.errors_in_variables import uncertain_conditions
from calib.calibration.map_fit import MapFit
from calib.calibration.noise import initial_sigma
from calib.calibration.problem import LeastSquaresProblem, ProblemStatement
from calib.calibration.result import CalibrationResult
from calib.calibration.result_assembly import assemble_result
from calib.calibration.settings import CalibrationSettings
from calib.calibration.truncated_fit import TruncatedFit
from calib.calibration.uncertainty_terms import ModelTerms
from calib.errors import InputError
from calib.measurements import Measurements, check_channels, ml_noise
from calib.types import nominal_vector

log = logging.getLogger(__name__)

__all__ = ["Calibrator", "calibrate"]

NOISE_SETTLED = 1e-3
"""Largest relative change of a channel's σ between two fits below which an estimated noise has settled [-]."""


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

    Attributes
    ----------
    statement : ProblemStatement
        The problem's statement, built once here (nominal values, scales, effective bounds
        [parameter units], prior, measured channels' columns); the problem the estimators solve,
        the uncertainty terms and the result's estimate read it, none holds a copy.
    terms : ModelTerms
        The model-derived uncertainty terms of this problem.
    """

    def __init__(self, model, measurements: Measurements, settings: CalibrationSettings | None = None,
                 callback: Callable[[dict], None] | None = None, name: str = "calibration",
                 start: np.ndarray | None = None):
        self.model = model
        self.measurements = measurements
        self.settings = (settings or CalibrationSettings()).validate()
        self.name = name
        self._callbacks = [c for c in (callback, _progress_printer if self.settings.verbose else None) if c]
        self.field = model.correction_field() if model.capabilities.correction_field else None
        self.statement = self._state_problem(model, measurements)
        self.start = None
        if start is not None:
            p0 = self.statement.p0
            start = np.asarray(start, float)
            if start.shape != p0.shape or not np.all(np.isfinite(start)):
                raise InputError(f"must be {p0.size} finite values, got shape {start.shape}", "Calibrator",
                                 field="start")
            self.start = np.clip(start, self.statement.lower, self.statement.upper)
        self.history: list[dict] = []
        st = self.settings
        self.terms = ModelTerms(model, self.field, st, measurements, self.statement)
        self.fitter = MapFit(self) if st.estimator == "map" else TruncatedFit(self)

    # ------------------------------------------------------------------ setup
    def _state_problem(self, model, measurements: Measurements) -> ProblemStatement:
        """The problem's statement (:class:`calib.calibration.problem.ProblemStatement`), checked:
        the measured channels' columns, the nominal values, scales (> 0), effective bounds (the
        correction field's lower bounds applied, ``cd_min``) and the prior (``prior_std`` of the
        settings by parameter name, else the parameter's own, else ``prior_sigma`` × scale)."""
        parameters = tuple(model.parameters)
        model_channels = [c.name for c in model.channels]
        check_channels(measurements, model_channels)
        channel_index = [model_channels.index(c) for c in measurements.channels]
        p0 = nominal_vector(parameters)
        scale = np.array([q.scale for q in parameters], float)
        if np.any(~(scale > 0)):
            j = int(np.flatnonzero(~(scale > 0))[0])
            raise InputError(f"parameter scale must be > 0, got {scale[j]!r}", "model.parameters",
                             field=parameters[j].name)
        lower = np.array([q.lower for q in parameters], float)
        upper = np.array([q.upper for q in parameters], float)
        if self.field is not None:
            lower = self.field.lower_bounds(lower, p0, self.settings.cd_min)
        stated = dict(self.settings.prior_std or {})
        names = [q.name for q in parameters]
        for name in stated:
            if name not in names:
                close = difflib.get_close_matches(name, names, 1)
                raise InputError(f"no parameter {name!r} in this model" + (f"; did you mean {close[0]!r}?" if close
                                                                            else f"; parameters: {', '.join(names)}"),
                                 "settings", field=f"calibration.prior_std.{name}")
        prior_std = np.array([stated[q.name] if q.name in stated else q.prior_std if np.isfinite(q.prior_std)
                              else self.settings.prior_sigma * q.scale for q in parameters], float)
        # a prior someone stated: the correction nodes' smooth-field prior, a parameter's own, the settings'
        prior_stated = np.array([q.name in stated or bool(np.isfinite(q.prior_std)) for q in parameters], bool)
        if self.field is not None:
            lay = self.field.layout
            for idx in (lay.lift_index, lay.drag_index):
                prior_stated[idx[idx >= 0]] = True
        return ProblemStatement(parameters, p0, scale, lower, upper, prior_std, prior_stated, tuple(channel_index))

    def emit(self, rec: dict) -> None:
        """Record a progress record and pass it to the callbacks."""
        self.history.append(rec)
        for cb in self._callbacks:
            cb(rec)

    # ------------------------------------------------------------------ run
    def run(self) -> CalibrationResult:
        """Calibrate; returns a :class:`CalibrationResult`."""
        t0 = time.perf_counter()
        st = self.settings
        m = self.measurements
        sigma_u = uncertain_conditions(m, st)   # None: the output-error fit below, as before
        sigma = initial_sigma(self.measurements, self.settings)
        statement = self.statement
        problem = LeastSquaresProblem(self.model, m.conditions, m.values,
                                      sigma if sigma is not None else np.ones_like(m.values), statement)
        # with exact derivatives a Jacobian costs little more than the values, and the estimators
        # linearize at the nominal values first: linearized here, the first iteration finds it cached
        starts_at_nominal = sigma is not None and self.start is None and self.model.capabilities.derivatives == "exact"
        nominal = problem.linearize(statement.p0) if starts_at_nominal else problem.evaluate(statement.p0)
        if nominal.n_failed == len(m.conditions):
            from calib.errors import ModelError

            raise ModelError(f"the nominal model fails at every point: {nominal.evaluation.failure_summary()}")
        if sigma is None:  # ML noise: start from the nominal residual
            resid = m.values - nominal.evaluation.values[:, statement.channel_index]
            sigma = np.broadcast_to(ml_noise(resid, nominal.ok), m.values.shape).copy()
            problem = problem.with_sigma(sigma)
        noise_iters = st.max_noise_iterations if st.noise in ("ml", "relative_ml") else 1
        p = statement.p0.copy() if self.start is None else self.start.copy()
        if sigma_u is not None:   # errors in variables
            problem, fit, message = fit_errors_in_variables(self, problem, sigma_u, p)
            p, status, noise_iters = fit.p, fit.status, 0
        for k_noise in range(noise_iters):
            fit = self.fitter.fit(problem, p)
            p, svd, lin, status, message = fit.p, fit.svd, fit.lin, fit.status, fit.message
            if st.noise not in ("ml", "relative_ml"):
                break
            if st.noise == "relative_ml":
                # one ML factor on the stated σ of every channel, with N − k degrees of freedom
                from calib.calibration.noise import ml_scale
                n_res = int(lin.ok.sum()) * len(statement.channel_index)
                fitted = float(np.sum(svd.singular_values ** 2 / (1.0 + svd.singular_values ** 2))) \
                    if st.estimator == "map" else svd.n_retained     # the MAP's effective number of parameters
                k_hat = ml_scale(float(np.sum(lin.residual[lin.ok] ** 2)), n_res, fitted)
                new_sigma = problem.sigma * k_hat
            else:
                resid = m.values - lin.evaluation.values[:, statement.channel_index]
                new_sigma = np.broadcast_to(ml_noise(resid, lin.ok), m.values.shape).copy()
            change = float(np.max(np.abs(new_sigma[0] / problem.sigma[0] - 1.0)))
            self.emit({"stage": "noise", "iteration": k_noise + 1, "sigma": new_sigma[0].tolist(),
                        "change": change})
            problem = problem.with_sigma(new_sigma)
            if change < NOISE_SETTLED:
                break
        if st.noise in ("ml", "relative_ml") and sigma_u is None:
            # the estimator's message is the last fit's: say how many fits the noise estimate took
            settled = change < NOISE_SETTLED
            message = (f"{message}; noise σ estimated over {k_noise + 1} fit(s), "
                       + (f"settled (last change {change:.2g} < {NOISE_SETTLED:g})" if settled else
                          f"NOT settled after max_noise_iterations = {noise_iters} (last change {change:.2g}, "
                          f"settled below {NOISE_SETTLED:g}): σ and the covariance are those of the last fit"))
        lin = problem.linearize(p)
        res = self.fitter.finish(problem, nominal, lin, status, message)
        res.provenance.wall_time = time.perf_counter() - t0    # once the result is whole, its terms included
        return res

    def prior_cov_scaled(self) -> np.ndarray:
        """The stated prior covariance of the scaled parameters [scale units²]
        (:meth:`calib.calibration.uncertainty_terms.ModelTerms.prior_cov_scaled`)."""
        return self.terms.prior_cov_scaled()

    # ------------------------------------------------------------------ outputs
    def result(self, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs, status, message,
               **extra) -> CalibrationResult:
        """The result of either estimator (:func:`calib.calibration.result_assembly.assemble_result`), with the
        history, the automatic truncation's record and the run's name."""
        truncation = self.fitter.truncation_record()
        # wall time 0 here: run() sets it once the result is whole (the assembly's model calls included)
        return assemble_result(self.terms, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs,
                               status, message, 0.0, history=self.history, truncation=truncation, name=self.name,
                               **extra)


def calibrate(model, measurements: Measurements, **settings) -> CalibrationResult:
    """Shortcut: ``Calibrator(model, measurements, CalibrationSettings(**settings)).run()``."""
    callback = settings.pop("callback", None)
    name = settings.pop("name", "calibration")
    return Calibrator(model, measurements, CalibrationSettings(**settings), callback, name).run()
