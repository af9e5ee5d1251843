"""The maximum a posteriori estimator of the Calibrator (``estimator = "map"``, the default): the
estimate under the stated prior by damped Gauss–Newton in prior-whitened coordinates
(:meth:`MapFit.fit`), and the Laplace covariance at it with the MAP's self-check against the
maximum-likelihood fit (:meth:`MapFit.finish`).

References
----------
D.J.C. MacKay, Bayesian interpolation, Neural Comput. 4 (1992) 415-447.
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006), ch. 3.
"""

from __future__ import annotations

import logging

import numpy as np

from calib.calibration.gauss_newton import EstimationStatus, StopRule, estimate_map
from calib.calibration.map_agreement import map_ml_agreement
from calib.calibration.outcome import FitOutcome
from calib.calibration.problem import LeastSquaresProblem
from calib.calibration.result import CalibrationResult
from calib.calibration.uncertainty import laplace_covariance, map_fit_scale, map_gain, prior_whitened_svd
from calib.checks.prior_check import psd_sqrt

log = logging.getLogger(__name__)

FLAT_PRIOR = 1e3
"""Prior 1-σ [scale units] the MAP estimator gives a parameter without a stated prior (no
``Parameter.prior_std``, not in ``prior_std``, not a correction node): flat for any data that
determine it to better than a thousand scales, so such a parameter is estimated by maximum
likelihood, and one the data cannot determine shows its σ unbounded instead of a prior nobody stated."""
MAP_DECREASE = 5e-4
"""Cost decrease [-] (half a χ²) below which the MAP iteration stops: the last step was then about
√(2 × 5e-4) = 0.03 posterior standard deviations long (:class:`calib.calibration.gauss_newton.StopRule`). On the
wind-tunnel coverage twin (c) (seed 5003) the Gauss–Newton converges linearly near the bounds: stopping
at a relative decrease of 1e-9 the calibration made 15 model Jacobians in all, with this rule 9."""
MAP_NOISE_DECREASE = 5e-3
"""For a model without exact derivatives (an FMU: a simulator whose outputs jump at the noise level of its
inner iterations), a step rejected while the undamped Gauss–Newton step predicts at most this decrease [-]
(half a χ²) ends the MAP as converged to the model's noise (``StopRule.noise_decrease``): the estimate is
then within √(2 × 5e-3) = 0.1 posterior standard deviations of the linearized model's minimum, and the
cost did not fall along the way there. On ``bench_fmu_run`` the damping otherwise rose through 15 rejected
trial steps along the weak direction, where the cost is flat to the FMU's output jumps."""


class MapFit:
    """The MAP estimator of a :class:`~calib.calibration.calibrator.Calibrator`.

    Parameters
    ----------
    cal : Calibrator
        Its settings, problem statement (prior, scales, bounds), problem terms and progress records.
    """

    def __init__(self, cal):
        self.cal = cal

    def truncation_record(self) -> dict:
        """The MAP has no retained count to choose: ``{}``."""
        return {}

    def prior_cov_scaled(self) -> np.ndarray:
        """The prior of the MAP estimator [scale units²]: the stated prior, and ``FLAT_PRIOR`` for
        the parameters without one."""
        P = self.cal.prior_cov_scaled()
        flat = np.flatnonzero(~self.cal.statement.prior_stated)
        P[flat, :], P[:, flat] = 0.0, 0.0
        P[flat, flat] = FLAT_PRIOR ** 2
        return P

    def fit(self, problem: LeastSquaresProblem, p: np.ndarray) -> FitOutcome:
        """The maximum a posteriori estimate under the stated prior (``estimator = "map"``).

        min ½‖R^(−½) r(p)‖² + ½ p̃ᵀP⁻¹p̃ under the bounds, by the damped Gauss–Newton of
        :func:`calib.calibration.gauss_newton.estimate_map` in the prior-whitened coordinates u (p̃ = L u,
        P = L Lᵀ), where the prior term is ½‖u‖² (MacKay 1992; Rasmussen & Williams 2006,
        ch. 3, on the Laplace approximation). There is no retained set to settle: the status is
        the estimator's (``converged``, ``max_iterations``, ``stalled``, ``failed``).
        """
        st = self.cal.settings
        L = psd_sqrt(self.prior_cov_scaled())
        u0 = np.linalg.lstsq(L, problem.scaled(p), rcond=None)[0]
        noisy = problem.model.capabilities.derivatives != "exact"
        out = estimate_map(problem, L, u0, st.optimizer,
                           StopRule(st.max_iterations, st.tolerance, decrease_tolerance=MAP_DECREASE,
                                    noise_decrease=MAP_NOISE_DECREASE if noisy else 0.0),
                           callback=self.cal.emit, stage="map",
                           broyden=noisy and st.jacobian_updates in ("auto", "broyden"))
        status = "failed" if out.status == EstimationStatus.QP_FAILED else str(out.status)
        lin = out.linearization
        sv, W, L = self.decomposition(lin)
        analysis = laplace_covariance(sv, L @ W).directions
        self.cal.emit({"stage": "map_done", "status": status, "cost": out.cost, "iterations": out.iterations, "rejected": out.rejected,
                       "broyden_updates": out.broyden_updates,
                    "data_beat_prior": analysis.n_retained, "n_failed": lin.n_failed})
        return FitOutcome(out.p, analysis, lin, status, out.message)

    def decomposition(self, lin):
        """The SVD of the prior-whitened sensitivities at ``lin`` (:func:`calib.calibration.uncertainty.prior_whitened_svd`,
        P = L Lᵀ the MAP's prior): s (descending), W and L."""
        L = psd_sqrt(self.prior_cov_scaled())
        return (*prior_whitened_svd(lin.M, L), L)

    def finish(self, problem, nominal, lin, status: str, message: str) -> CalibrationResult:
        """The result of ``estimator = "map"``: the Laplace covariance at the estimate, widened by
        the fit scale (the noise variance multiplied by max(1, χ²/(N − n_eff)), n_eff = Σ s²/(1+s²)
        the effective number of parameters; MacKay 1992) with a stated noise and ``scale_by_fit``."""
        st = self.cal.settings
        s, W, L = self.decomposition(lin)
        LW = L @ W
        fit_scale, n_eff = map_fit_scale(float(np.sum(lin.residual[lin.ok] ** 2)),
                                         int(lin.ok.sum()) * len(self.cal.statement.channel_index), s,
                                         st.scale_by_fit and st.noise not in ("ml", "relative_ml"))
        laplace = laplace_covariance(s, LW, fit_scale)
        svd, cov, cov_weak = laplace.directions, laplace.total, laplace.weak
        ev = lin.evaluation
        alpha_seen, eta_seen = self.cal.field.seen(ev) if self.cal.field is not None else (np.zeros(0), np.zeros(0))
        gain = map_gain(LW, s, lin.M)
        alias, _, alias_note, fine = self.cal.terms.aliasing(problem, lin, svd, alpha_seen, eta_seen, gain=gain)
        cov_alias = np.zeros_like(cov)
        if alias is not None:   # the field between the nodes, taken up by the estimate
            cov, cov_alias = cov + alias, alias
        u_hat = np.linalg.lstsq(L, problem.scaled(lin.p), rcond=None)[0]
        c = np.linalg.norm(LW, axis=0)
        theta_hat = (np.where(c > 0, c, 1.0) * (W.T @ u_hat))[svd.retained]
        prior_var = np.diag(self.prior_cov_scaled())
        obs = np.clip(1.0 - np.diag(cov) / np.where(prior_var > 0, prior_var, 1.0), 0.0, 1.0)
        try:
            prior_check = self.cal.terms.prior_check(problem, lin, fine)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError) as exc:   # a check, not the result
            prior_check = {"failed": f"{type(exc).__name__}: {exc}"}
        multiple_roots = np.asarray(ev.extras.get("multiple_roots", np.zeros(len(ev.status), bool)), bool)
        statement = self.cal.statement
        D = np.outer(statement.scale, statement.scale)
        self.cal.emit({"stage": "map_covariance", "n_eff": n_eff, "fit_scale": fit_scale})
        agreement = map_ml_agreement(lin.M, lin.residual.reshape(-1), problem.scaled(lin.p),
                                     self.prior_cov_scaled(), problem.scaled(statement.lower),
                                     problem.scaled(statement.upper), [q.name for q in statement.parameters], fit_scale)
        self.cal.emit({"stage": "map_agreement", "ok": agreement.ok, "max_z": agreement.max_z,
                    "n_fixed": agreement.n_fixed})
        if not agreement.ok:
            log.warning("%s: %s", self.cal.name, agreement.sentence())
            message = f"{message}; {agreement.sentence()}" if message else agreement.sentence()
        return self.cal.result(problem, nominal, lin, svd, cov * D, cov_weak * D,
                            np.diag(svd.sigma_theta[svd.retained] ** 2), theta_hat, obs, status, message,
                            checks={"MAP and ML": agreement.sentence()},
                            fit_scale=fit_scale, prior_check=prior_check, multiple_roots=multiple_roots,
                            aliasing_note=alias_note, gain=gain if alias is not None else np.zeros((0, 0)),
                            cov_alias=cov_alias * D)
