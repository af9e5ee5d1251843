"""The estimators' covariances, assembled from named parts (pure functions, no model calls).

The truncated estimator's :func:`truncated_covariance`; the MAP estimator's Laplace covariance
from the SVD of the prior-whitened sensitivities (:func:`prior_whitened_svd`,
:func:`laplace_covariance`, :func:`map_fit_scale`, :func:`map_gain`).

The terms that need the model (the field between the nodes, the frozen directions through the
model's curvature, the fold-dominated directions) are computed by the calibrator; this module puts
them together in one documented order (docs/theory.md, Uncertainty) and keeps each part by name.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.identifiability import SvdAnalysis, frozen_aware_covariance


@dataclass(frozen=True)
class TruncatedCovariance:
    """Covariance of the scaled parameters p̃ under the truncated estimator, by parts [scale units²].

    Attributes
    ----------
    noise : ndarray
        The retained θ's covariance from the measurement noise, frozen-aware
        (:func:`calib.calibration.identifiability.frozen_aware_covariance`).
    aliasing : ndarray
        The field between the nodes that the retained θ take up (zeros when the term is left out).
    fit_scale : float
        max(1, χ²/dof) with ``scale_by_fit`` and a stated noise, else 1: multiplies noise + aliasing.
    curvature : ndarray
        The frozen directions' prior through the model's curvature (zeros when left out).
    fold : ndarray
        The prior variance added along retained directions that points with several BEM roots determine.
    frozen : ndarray
        The frozen directions' prior.
    """

    noise: np.ndarray
    aliasing: np.ndarray
    fit_scale: float
    curvature: np.ndarray
    fold: np.ndarray
    frozen: np.ndarray

    @property
    def retained(self) -> np.ndarray:
        """The retained directions' part: (noise + aliasing) · fit_scale + curvature + fold."""
        return (self.noise + self.aliasing) * self.fit_scale + self.curvature + self.fold

    @property
    def total(self) -> np.ndarray:
        """Cov(p̃): the retained part and the frozen directions' prior."""
        return self.retained + self.frozen


def in_parameters(V_retained: np.ndarray, cov_theta_part: np.ndarray | None, n: int) -> np.ndarray:
    """A covariance over the retained θ taken to the scaled parameters (V_r C V_rᵀ); zeros for None."""
    if cov_theta_part is None:
        return np.zeros((n, n))
    return V_retained @ cov_theta_part @ V_retained.T


def fold_inflation(V_retained: np.ndarray, fold_thetas, cov_retained: np.ndarray, prior_cov: np.ndarray):
    """The prior variance along each fold-dominated retained direction (1-based θ numbers), added to
    ``cov_retained`` in turn: the added matrix and the σ along each direction before and after [scale units]."""
    added = np.zeros_like(cov_retained)
    sigmas = {}
    for theta in sorted(set(fold_thetas)):
        v = V_retained[:, theta - 1]
        now = cov_retained + added
        before = float(np.sqrt(max(v @ now @ v, 0.0)))
        added = added + float(v @ prior_cov @ v) * np.outer(v, v)
        sigmas[theta] = {"sigma_before": before, "sigma_after": float(np.sqrt(max(v @ (cov_retained + added) @ v, 0.0)))}
    return added, sigmas


def truncated_covariance(V: np.ndarray, sigma_theta: np.ndarray, retained: np.ndarray, prior_cov: np.ndarray,
                         aliasing_theta: np.ndarray | None, fit_scale: float, curvature_theta: np.ndarray | None,
                         fold_thetas=()) -> tuple[TruncatedCovariance, dict]:
    """Assemble :class:`TruncatedCovariance` from the SVD (``V``, ``sigma_theta``, ``retained``), the prior of
    p̃, and the model-derived terms over the retained θ (None: left out); returns it and the fold
    directions' σ before and after (by θ number)."""
    n = V.shape[0]
    noise, frozen = frozen_aware_covariance(V, sigma_theta, retained, prior_cov)
    Vr = V[:, retained]
    aliasing = in_parameters(Vr, aliasing_theta, n)
    curvature = in_parameters(Vr, curvature_theta, n)
    before_fold = (noise + aliasing) * fit_scale + curvature
    fold, sigmas = fold_inflation(Vr, fold_thetas, before_fold, prior_cov)
    return TruncatedCovariance(noise, aliasing, fit_scale, curvature, fold, frozen), sigmas


def prior_whitened_svd(M: np.ndarray, L: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The SVD of the prior-whitened sensitivities A = M L = U S Wᵀ (M the whitened scaled
    sensitivities, P = L Lᵀ the prior of p̃): the singular values s (descending) and W."""
    A = M @ L
    lam, W = np.linalg.eigh(A.T @ A)
    order = np.argsort(lam)[::-1]
    return np.sqrt(np.clip(lam[order], 0.0, None)), W[:, order]


@dataclass(frozen=True)
class LaplaceCovariance:
    """The MAP estimate's Laplace covariance of p̃, by parts [scale units²].

    Attributes
    ----------
    directions : SvdAnalysis
        The directions p̃ ∝ L w_i as unit columns of V, s_i, the σ of each direction's coordinate
        [scale units], and "retained" = s_i > 1: the data determine that direction better than the prior.
    total : ndarray, shape (n, n)
        (G̃ᵀR⁻¹G̃/k + P⁻¹)⁻¹ = L W (I + S²/k)⁻¹ (L W)ᵀ.
    weak : ndarray, shape (n, n)
        Its part along the directions where the prior dominates (s_i ≤ 1).
    """

    directions: SvdAnalysis
    total: np.ndarray
    weak: np.ndarray


def laplace_covariance(s: np.ndarray, LW: np.ndarray, fit_scale: float = 1.0) -> LaplaceCovariance:
    """The Laplace covariance of the scaled parameters from :func:`prior_whitened_svd` (``LW`` = L W)
    with the noise variance multiplied by ``fit_scale`` = k (MacKay 1992; Rasmussen & Williams
    2006, ch. 3)."""
    shrink = 1.0 / (1.0 + s ** 2 / fit_scale)
    cov = (LW * shrink) @ LW.T
    weak = s <= 1.0
    cov_weak = (LW[:, weak] * shrink[weak]) @ LW[:, weak].T
    c = np.linalg.norm(LW, axis=0)
    c = np.where(c > 0, c, 1.0)
    return LaplaceCovariance(SvdAnalysis(s, LW / c, c * np.sqrt(shrink), 1.0, ~weak), cov, cov_weak)


def map_fit_scale(chi2: float, n_rows: int, s: np.ndarray, enabled: bool) -> tuple[float, float]:
    """The MAP's fit scale max(1, χ²/(N − n_eff)) (1 when not ``enabled`` or N ≤ n_eff) and
    n_eff = Σ s²/(1+s²), the effective number of parameters (MacKay 1992) [-]."""
    n_eff = float(np.sum(s ** 2 / (1.0 + s ** 2)))
    return (max(1.0, chi2 / (n_rows - n_eff)) if enabled and n_rows > n_eff else 1.0), n_eff


def map_gain(LW: np.ndarray, s: np.ndarray, M: np.ndarray) -> np.ndarray:
    """The MAP estimate's linear response to the whitened data, p̃̂ = gain r̃ with
    gain = L (AᵀA + I)⁻¹ Aᵀ, A = M L [scale units]."""
    return (LW / (1.0 + s ** 2)) @ (M @ LW).T
