"""Confidence bands of the corrected polars, and their coverage of a known true correction.

The band of ΔC(α, η) = B p̂ has the variance Bᵀ Cov(p̂) B, plus the representation variance
of the field between the nodes when the prior is given
(:func:`calib.parametrizations.field_prior.unresolved_variance`). The drag band respects the
bound C_D ≥ C_D,min the estimate obeys: where the Gaussian band would reach below it, it is
the shortest interval of the Gaussian truncated there (:func:`bounded_interval`). The bands
are what :meth:`calib.parametrizations.correction_field.CorrectionField.bands` and
:meth:`~calib.parametrizations.correction_field.CorrectionField.coverage` return.

References
----------
N.L. Johnson, S. Kotz, N. Balakrishnan, Continuous Univariate Distributions, vol. 1,
2nd ed., Wiley 1994, §10.1 (the truncated normal).
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def bounded_interval(estimate, std, lower, confidence: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Shortest interval of probability ``confidence`` of a Gaussian N(estimate, std²)
    truncated below at ``lower`` (the highest-density interval of the truncated density).

    Where the bound lies far below the estimate this is the usual estimate ± z·std; where it
    cuts into the Gaussian the interval starts at the bound and its upper end follows from
    the renormalized mass, so no value the bound excludes is stated possible (e.g. C_D below
    C_D,min) and the band is no wider than the truncated density needs.

    Parameters
    ----------
    estimate, std : array_like
        Mean and standard deviation of the untruncated Gaussian (broadcast).
    lower : array_like
        Lower bound; ``-inf`` for none.
    confidence : float
        Probability of the interval under the truncated density [-].

    Returns
    -------
    lo, hi : ndarray
        Interval ends (std = 0 gives the estimate raised to the bound).

    References
    ----------
    N.L. Johnson, S. Kotz, N. Balakrishnan, Continuous Univariate Distributions, vol. 1,
    2nd ed., Wiley 1994, §10.1 (the truncated normal).
    """
    mu, s, L = np.broadcast_arrays(np.asarray(estimate, float), np.asarray(std, float), np.asarray(lower, float))
    lo, hi = np.empty(mu.shape), np.empty(mu.shape)
    flat = s <= 0
    lo[flat] = hi[flat] = np.maximum(mu[flat], L[flat])
    k = ~flat
    mu, s, L = mu[k], s[k], L[k]
    a = (L - mu) / s                                   # the bound in standard units
    mass = stats.norm.sf(a)                            # Gaussian mass above the bound
    c = stats.norm.ppf(0.5 + 0.5 * confidence * mass)  # symmetric half-width holding `confidence` of it
    symmetric = -c >= a
    # otherwise the interval starts at the bound: P(a < Z < u) = confidence · mass
    with np.errstate(divide="ignore"):
        u = stats.norm.isf((1 - confidence) * mass)
        # far in the tail (mass below the smallest double) the truncated density is the
        # exponential of rate a/std beyond the bound (Mills' ratio)
        tail = L + s * -np.log1p(-confidence) / np.maximum(a, 1.0)
    lo[k] = np.where(symmetric, mu - c * s, L)
    hi[k] = np.where(symmetric, mu + c * s, np.where(np.isfinite(u), mu + u * s, tail))
    return lo, hi


def quadratic_diagonal(B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """diag(B C Bᵀ) without forming it: Σ_jk B_ij C_jk B_ik per row, one matrix product (BLAS) and
    one row sum; numpy's three-operand einsum loops over i, j, k in C instead (over 10× slower at
    121 × 5 points and 61 parameters). Equal to round-off."""
    return np.sum((B @ C) * B, axis=1)


def polar_bands(field, p_hat: np.ndarray, cov_p: np.ndarray, cov_frozen: np.ndarray | None, alpha_deg, eta,
                confidence: float, prior_std: np.ndarray | None, correlation_length: float,
                cd_min: float | None) -> dict:
    """Corrected polars C = C₀ + ΔC(α, η; p̂) with two-sided confidence bands.

    Parameters
    ----------
    field : CorrectionField
        The field (its basis, representation variance, drag floor and nominal polars).
    p_hat, cov_p, cov_frozen, alpha_deg, eta, confidence, prior_std, correlation_length, cd_min
        As :meth:`calib.parametrizations.correction_field.CorrectionField.bands`.

    Returns
    -------
    dict
        As :meth:`calib.parametrizations.correction_field.CorrectionField.bands` (empty
        without a node grid).
    """
    grid = field.grid
    if grid is None:
        return {}
    a_nodes = grid.alpha_nodes_deg
    alpha = np.linspace(a_nodes[0], a_nodes[-1], 121) if alpha_deg is None else np.asarray(alpha_deg, float)
    eta = grid.eta_nodes if eta is None else np.asarray(eta, float)
    A, E = np.meshgrid(alpha, eta)
    z = stats.norm.ppf(0.5 * (1 + confidence))
    out = {"alpha_deg": alpha, "eta": eta, "confidence": np.array(confidence)}
    for block, letter in (("lift", "cl"), ("drag", "cd")):
        Bf = field.basis(A, E, block)
        out[f"d{letter}"] = (Bf @ p_hat).reshape(A.shape)
        rep = 0.0 if prior_std is None else \
            field.representation_variance(A, E, block, prior_std, correlation_length).reshape(A.shape)
        var = np.maximum(quadratic_diagonal(Bf, cov_p), 0.0).reshape(A.shape) + rep
        out[f"d{letter}_half_width"] = z * np.sqrt(var)
        floor = field.drag_floor(A, E, cd_min) if block == "drag" else -np.inf
        out[f"d{letter}_lower"], out[f"d{letter}_upper"] = bounded_interval(out[f"d{letter}"], np.sqrt(var),
                                                                            floor, confidence)
        if cov_frozen is not None:
            vf = np.maximum(quadratic_diagonal(Bf, cov_frozen), 0.0).reshape(A.shape) + rep
            out[f"d{letter}_prior_fraction"] = np.where(var > 0, vf / np.where(var > 0, var, 1.0), 1.0)
    if field.nominal_coefficients is not None:
        cl0, cd0 = field.nominal_coefficients(A, E)
        out["cl0"], out["cd0"] = np.asarray(cl0, float), np.asarray(cd0, float)
    return out


def band_coverage(field, p_hat: np.ndarray, cov_p: np.ndarray, alpha_deg, eta, truth_dcl, truth_dcd,
                  confidence: float, prior_std: np.ndarray | None, correlation_length: float,
                  cd_min: float | None) -> dict:
    """Fraction of points (α, η) where the band contains a known true correction.

    Parameters
    ----------
    field : CorrectionField
        The field (its basis, representation variance and drag floor).
    p_hat, cov_p, alpha_deg, eta, truth_dcl, truth_dcd, confidence, prior_std, correlation_length, cd_min
        As :meth:`calib.parametrizations.correction_field.CorrectionField.coverage`.

    Returns
    -------
    dict
        ``lift``, ``drag``: covered fraction [-]; ``n_points``, ``confidence``.
    """
    out = {"n_points": int(np.size(alpha_deg)), "confidence": confidence}
    for block, truth in (("lift", truth_dcl), ("drag", truth_dcd)):
        Bf = field.basis(alpha_deg, eta, block)
        est = Bf @ p_hat
        var = np.maximum(quadratic_diagonal(Bf, cov_p), 0.0)
        if prior_std is not None:
            var = var + field.representation_variance(alpha_deg, eta, block, prior_std, correlation_length)
        floor = field.drag_floor(alpha_deg, eta, cd_min).reshape(-1) if block == "drag" else -np.inf
        lo, hi = bounded_interval(est, np.sqrt(var), floor, confidence)
        t = np.asarray(truth, float).reshape(-1)
        out[block] = float(np.mean((t >= lo) & (t <= hi))) if est.size else float("nan")
    return out
