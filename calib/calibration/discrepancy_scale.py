"""The estimate's covariance beside a fitted model discrepancy: the misfit counted once.

With a stated noise and ``scale_by_fit``, the MAP estimator multiplies the noise variance of its
Laplace covariance by the fit scale k = max(1, χ²/(N − n_eff)) (:func:`calib.calibration.uncertainty.map_fit_scale`):
a misfit beyond the noise widens the parameters' intervals. Where a prediction also carries the
model discrepancy fitted to the same residuals (:mod:`calib.calibration.discrepancy`), that misfit
would count twice: once through k in the parameters and once through the discrepancy's variance.
In the formulation of Kennedy & O'Hagan (2001) the discrepancy is part of the likelihood's
covariance, z − y(p) ~ N(0, R + Σ_δ); the misfit it explains is not noise. So where a prediction
carries a fitted discrepancy, :func:`discrepancy_aware_covariance` recomputes the fit scale from the
residuals whitened by R + Σ_δ over the channels the discrepancy covers (R alone over the others),

.. math::
    χ'^2 = \\sum_{c \\notin δ} \\sum_k (r_{kc}/σ_{kc})^2 + \\sum_{c \\in δ} r_c^T (S_c + U_c Σ_{δ,c} U_c)^{-1} r_c,
    \\qquad k' = \\max\\bigl(1, χ'^2 / (N − n_{eff})\\bigr),

(S_c the noise variances, U_c the process's unit at the calibration points, Σ_δ,c = τ²K_ℓ its prior
covariance there) and re-forms the Laplace covariance with k' in place of k
(:func:`reformed_laplace_covariance`): (G̃ᵀR⁻¹G̃/k' + P⁻¹)⁻¹, a function of the singular values s,
the directions L W and k alone, recovered from the result. k' ≤ k always; k' = k where no channel
carries a discrepancy. What remains of k' above 1 is misfit the discrepancy does not explain.

This is the modular ("cut") treatment of Liu, Bayarri & Berger (2009), as the discrepancy itself is
fitted: the parameters keep the sensitivities' information under the noise R, the discrepancy carries
the misfit. It is not the full Kennedy–O'Hagan posterior of the parameters under R + Σ_δ, which is
wider along directions the discrepancy can mimic, and whose prediction then needs the correlation
between the parameters and the discrepancy (Rasmussen & Williams 2006, eq. 2.42); the tests compare
both on a linear-Gaussian problem.

The truncated estimator's covariance is left as recorded (its parts are not stored separately).

References
----------
M.C. Kennedy, A. O'Hagan, Bayesian calibration of computer models, J. R. Stat. Soc. B 63 (2001) 425-464.
F. Liu, M.J. Bayarri, J.O. Berger, Modularization in Bayesian analysis, with emphasis on analysis of
computer models, Bayesian Analysis 4 (2009) 119-150.
D.J.C. MacKay, Bayesian interpolation, Neural Comput. 4 (1992) 415-447.
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006), ch. 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.uncertainty import laplace_covariance, map_fit_scale

__all__ = ["EstimateCovariance", "discrepancy_aware_covariance", "discrepancy_chi2", "reformed_laplace_covariance"]


@dataclass(frozen=True)
class EstimateCovariance:
    """The covariance of p̂ a prediction uses, and why.

    Attributes
    ----------
    cov_p : ndarray, shape (n, n)
        Cov(p̂) [parameter units²].
    fit_scale : float
        The noise-variance factor in it [-]: k' where re-formed, else the recorded k.
    recorded_fit_scale : float
        The result's k [-].
    chi2 : float
        χ'² of the calibration residuals under R + Σ_δ (NaN where not computed) [-].
    reformed : bool
        Whether ``cov_p`` was re-formed with k'.
    note : str
        A sentence on it ('' where nothing applies).
    """

    cov_p: np.ndarray
    fit_scale: float
    recorded_fit_scale: float
    chi2: float
    reformed: bool
    note: str


def reformed_laplace_covariance(result, fit_scale: float) -> np.ndarray:
    """The MAP result's Cov(p̂) with the noise variance multiplied by ``fit_scale`` instead of the recorded k
    [parameter units²].

    The recorded directions are V = L W / c (unit columns, c = ‖(L W)_i‖) and σ(θ_i) = c_i (1 + s_i²/k)^(−½)
    (:func:`calib.calibration.uncertainty.laplace_covariance`), so L W = V diag(σ(θ) (1 + s²/k)^½) and the
    covariance is re-formed as D (L W (I + S²/k')⁻¹ (L W)ᵀ) D + Cov_alias (D the scales; the aliasing term
    does not carry k). With ``fit_scale`` = k it is the recorded ``cov_p`` to round-off.
    """
    ident, unc = result.identifiability, result.uncertainty
    s = np.asarray(ident.singular_values, float)
    k = float(unc.fit_scale)
    c = np.asarray(ident.sigma_theta, float) * np.sqrt(1.0 + s ** 2 / k)
    LW = np.asarray(ident.V, float) * c
    d = np.asarray(result.estimate.scale, float)
    cov = laplace_covariance(s, LW, float(fit_scale)).total * np.outer(d, d)
    alias = np.asarray(unc.cov_alias, float)
    return cov + alias if alias.shape == cov.shape else cov


def discrepancy_chi2(result, disc) -> tuple[float, int]:
    """χ'² of the calibration residuals whitened by R + Σ_δ over the channels ``disc`` covers (R alone over
    the others; module notes) and the number of rows N it sums over [-].

    Parameters
    ----------
    result : CalibrationResult
    disc : calib.calibration.discrepancy.Discrepancy
        Fitted to ``result`` (:func:`calib.calibration.discrepancy.fit_discrepancy`).
    """
    fit = result.fit
    ok = fit.status_after == 0
    r = np.asarray(fit.measured, float) - np.asarray(fit.model_after, float)
    sigma = np.asarray(fit.sigma, float)
    x = disc.features(result.conditions, result.provenance.rotor_radius)
    chi2 = 0.0
    for j, c in enumerate(result.channels):
        w = np.where(ok & (sigma[:, j] > 0), r[:, j] / np.where(sigma[:, j] > 0, sigma[:, j], 1.0), 0.0)
        q = disc.processes.get(c)
        if q is None:
            chi2 += float(np.sum(w ** 2))
            continue
        y = np.asarray(fit.model_after[:, j], float)
        use = ok & np.isfinite(y) & np.isfinite(r[:, j]) & (np.abs(y) > 0) & (sigma[:, j] > 0)
        chi2 += float(np.sum(w[ok & ~use] ** 2))               # points the process does not describe
        u = q.unit(y[use])
        C = q.prior_covariance(x[use]) * np.outer(u, u) + np.diag(sigma[use, j] ** 2)
        L = np.linalg.cholesky(C)
        z = np.linalg.solve(L, r[use, j])
        chi2 += float(z @ z)
    return chi2, int(ok.sum()) * len(result.channels)


def discrepancy_aware_covariance(result, disc) -> EstimateCovariance:
    """Cov(p̂) for a prediction that carries the discrepancy ``disc`` (None: none): the recorded one, or
    for a MAP result whose fit scale k > 1 and some of whose channels carry a process, the Laplace
    covariance re-formed with k' (module notes; Kennedy & O'Hagan 2001: the discrepancy is part of
    the likelihood's covariance, so the misfit it explains does not also widen the parameters)."""
    unc = result.uncertainty
    k = float(unc.fit_scale)
    cov = np.asarray(unc.cov_p, float)
    if disc is None or not disc.processes or k <= 1.0 or result.estimator != "map":
        why = "" if disc is None or not disc.processes or k <= 1.0 else (
            f"; the {result.estimator} estimator's covariance keeps its fit scale k = {k:.3g} (not re-formed)")
        return EstimateCovariance(cov, k, k, float("nan"), False, why.lstrip("; "))
    chi2, n_rows = discrepancy_chi2(result, disc)
    k_new, _ = map_fit_scale(chi2, n_rows, np.asarray(result.identifiability.singular_values, float), True)
    k_new = min(k_new, k)
    note = (f"the parameters' covariance re-formed with the fit scale k' = {k_new:.3g} from the residuals "
            f"whitened by noise + discrepancy (recorded k = {k:.3g}): the misfit the discrepancy carries is "
            "not counted again in the parameters")
    return EstimateCovariance(reformed_laplace_covariance(result, k_new), k_new, k, chi2, True, note)
