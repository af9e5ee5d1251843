"""The covariance the frozen directions add through the model's curvature
(:func:`frozen_curvature_covariance`): where the model is not linear over the prior of the
directions the truncation froze, their prior draws move the retained estimate, and that spread
is added to the retained θ's covariance (docs/theory.md, Uncertainty).

References
----------
M.J. Box, Bias in nonlinear estimation, J. R. Stat. Soc. B 33 (1971) 171-201.
"""

from __future__ import annotations

import numpy as np

from calib.calibration.identifiability import prior_in


CURVATURE_SEED = 2014
"""Seed of the prior draws of :func:`frozen_curvature_covariance` (results are reproducible)."""


def frozen_curvature_covariance(residual_at, r0: np.ndarray, ok0: np.ndarray, M: np.ndarray, V: np.ndarray,
                                sigma_theta: np.ndarray, retained: np.ndarray, prior: np.ndarray,
                                n_samples: int, seed: int = CURVATURE_SEED) -> tuple[np.ndarray, dict]:
    r"""Covariance of the retained θ̂ from the truth's frozen components through the model's curvature.

    :func:`frozen_aware_covariance` is exact for a linear model: the frozen components δ of
    the truth move the outputs along U_NID ⟂ U_ID and leave θ̂_ID unbiased. A BEM is not
    linear over the prior's range (a node moved by one prior σ shifts α-dependent loads
    near stall), and the part of y(p̂ + δ) − y(p̂) that is not M δ,

    .. math::  n(δ) = r(p̂) − r(p̂ + δ) − M δ   (whitened),

    has a component along U_ID that the estimate takes up as signal. At a stationary
    point of the retained fit, U_IDᵀ(n + e) = 0 to first order in the retained error, so

    .. math::  Δθ_{ID}(δ) = −S_{ID}^{-2} V_{ID}^T M^T n(δ),

    and its second moment over δ ~ N(0, V_NID V_NIDᵀ P V_NID V_NIDᵀ) (mean included: n is
    even in δ to leading order, so it biases θ̂ rather than adding scatter) is estimated
    here by Monte Carlo. Quadratic in δ to leading order, n is uncorrelated with δ for a
    Gaussian prior, so this term adds to the two of :func:`calib.calibration.identifiability.frozen_aware_covariance` without
    a cross term. The term is largest where few θ are retained and the frozen part of the
    truth carries signal the linearization does not see (docs/theory.md, Uncertainty; on the bias that a
    model's curvature gives least-squares estimates: M.J. Box, Bias in nonlinear estimation,
    J. R. Stat. Soc. B 33 (1971) 171-201; Seber & Wild, *Nonlinear Regression*, Wiley 1989,
    ch. 4).

    Parameters
    ----------
    residual_at : callable
        ``residual_at(delta)`` with a scaled step δ (shape (n_params,)) returns the whitened
        residual at p̂ + D δ (flattened like the rows of ``M``), a bool mask of its rows that
        converged, and the step actually taken (after the bounds) [scale units].
    r0 : ndarray, shape (n_rows,)
        Whitened residual at p̂ [-].
    ok0 : ndarray of bool, shape (n_rows,)
        Rows that converged at p̂.
    M : ndarray, shape (n_rows, n_params)
        Whitened scaled sensitivities at p̂ (zero rows where not converged).
    V, sigma_theta, retained
        The SVD of ``M`` (:class:`SvdAnalysis`): right singular vectors, σ(θ_i) = 1/s_i
        [scale units], retained mask.
    prior : ndarray, shape (n_params, n_params) or (n_params,)
        Prior covariance P of the scaled parameters [scale units²] (or 1-σ per parameter).
    n_samples : int
        Prior draws of the frozen components.
    seed : int
        Seed of the draws.

    Returns
    -------
    cov : ndarray, shape (n_retained, n_retained)
        E[Δθ Δθᵀ] in the retained coordinates [scale units²].
    info : dict
        ``samples`` (drawn), ``used`` (with at least one converged row), ``samples_with_failed_points``
        (draws at which some point did not converge; those rows are left out of that draw).
    """
    retained = np.asarray(retained, bool)
    k = int(retained.sum())
    info = {"samples": int(n_samples), "used": 0, "samples_with_failed_points": 0}
    Vn = V[:, ~retained]
    if k == 0 or n_samples <= 0 or Vn.shape[1] == 0:
        return np.zeros((k, k)), info
    prior_theta = prior_in(Vn, prior)
    w, Q = np.linalg.eigh(0.5 * (prior_theta + prior_theta.T))
    root = Vn @ (Q * np.sqrt(np.clip(w, 0.0, None)))
    # Δθ = −S⁻² V_IDᵀ Mᵀ n: the rows of A = S⁻² V_IDᵀ Mᵀ map a whitened misfit to the retained θ
    A = (V[:, retained] * sigma_theta[retained] ** 2).T @ M.T
    acc = _sum_curvature_shifts(residual_at, r0, np.asarray(ok0, bool), M, A, root, int(n_samples), seed, info)
    return (acc / info["used"] if info["used"] else acc), info


def _sum_curvature_shifts(residual_at, r0: np.ndarray, ok0: np.ndarray, M: np.ndarray, A: np.ndarray,
                          root: np.ndarray, n_samples: int, seed: int, info: dict) -> np.ndarray:
    """Σ Δθ Δθᵀ over prior draws of the frozen components (the Monte Carlo of
    :func:`frozen_curvature_covariance`).

    Parameters
    ----------
    residual_at, r0, ok0, M
        As in :func:`frozen_curvature_covariance` (``ok0`` a bool array).
    A : ndarray, shape (n_retained, n_rows)
        S⁻² V_IDᵀ Mᵀ: maps a whitened misfit to the retained θ [scale units].
    root : ndarray, shape (n_params, n_frozen)
        Draws δ = ``root`` z with z ~ N(0, I) have the frozen components' prior covariance
        [scale units].
    n_samples, seed : int
        Prior draws and their seed.
    info : dict
        Its ``used`` and ``samples_with_failed_points`` are counted up, draw by draw.

    Returns
    -------
    ndarray, shape (n_retained, n_retained)
        The sum over the draws used [scale units²].
    """
    rng = np.random.default_rng(seed)
    acc = np.zeros((A.shape[0], A.shape[0]))
    for _ in range(n_samples):
        r, ok, step = residual_at(root @ rng.standard_normal(root.shape[1]))
        rows = ok0 & np.asarray(ok, bool)
        if not rows.all():
            info["samples_with_failed_points"] += 1
        if not rows.any():
            continue
        n = np.where(rows, (r0 - r) - M @ step, 0.0)
        d = A @ n
        acc += np.outer(d, d)
        info["used"] += 1
    return acc
