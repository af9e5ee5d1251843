"""The model discrepancy as a covariance across the power-curve bins: :func:`discrepancy_covariance`.

:func:`calib.calibration.prediction.predict_outputs` gives the model discrepancy's 1-σ per point
(:mod:`calib.calibration.discrepancy`: a Gaussian process δ(x) over the scaled tip-speed ratio,
pitch and wind speed, relative or in channel units, fitted to the calibration residuals; Kennedy & O'Hagan
2001). An integral quantity such as the AEP needs its covariance across the bins. Adding the
per-bin σ linearly over the bins treats the discrepancy as fully correlated, an upper bound
(Cauchy-Schwarz); the process itself says how correlated two bins are.

Notes
-----
The prediction keeps the calibrated model's value ŷ; the discrepancy adds its second moment at
the new points. Given the calibration residuals e (in the process's unit u: relative, u = |ŷ|, or
the channel's, u constant; noise variances S), the process at
new points x has the conditional mean μ = k(x)ᵀ (τ²K + S)⁻¹ e and covariance
Σ(x, x') = τ² k_ℓ(x, x') − k(x)ᵀ (τ²K + S)⁻¹ k(x'), with k(x) = τ² k_ℓ(x, X) and k_ℓ the
squared-exponential kernel exp(−Σ_d (x_d − x'_d)² / 2ℓ_d²) (Rasmussen & Williams 2006, eq. 2.24). The
error of the bins' outputs is u ∘ δ, so its second-moment matrix is

.. math::
    D_{ij} = u_i u_j (μ_i μ_j + Σ_{ij}),

whose diagonal is ``predict_outputs``' μ² + v per point times u² (the discrepancy σ², a test
checks it). The conditional mean is one realization common to all bins (fully correlated, with
its sign); the conditional variance is correlated over the kernel's length ℓ. An AEP c · P then
has the discrepancy's mean square cᵀ D c = (c · uμ)² + (c ∘ u)ᵀ Σ (c ∘ u) [W² h²].

References
----------
M.C. Kennedy, A. O'Hagan, Bayesian calibration of computer models, J. R. Stat. Soc. B 63 (2001) 425-464.
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006), ch. 2.
"""

from __future__ import annotations

import numpy as np

__all__ = ["discrepancy_correlation", "discrepancy_covariance", "discrepancy_moments"]


def _se_kernel(a: np.ndarray, b: np.ndarray, length) -> np.ndarray:
    """Squared-exponential kernel exp(−Σ_d (a_d − b_d)² / 2ℓ_d²) between the rows of ``a`` and ``b``
    (``length`` one ℓ or one per column) [-]."""
    d = (np.asarray(a, float)[:, None, :] - np.asarray(b, float)[None, :, :]) / np.asarray(length, float)
    return np.exp(-0.5 * (d ** 2).sum(axis=-1))


def discrepancy_moments(process, x_new: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Conditional mean μ (n,) and covariance Σ (n, n) of one channel's discrepancy process at the
    scaled conditions ``x_new`` (n, 3) [in the process's unit u, u²].

    Parameters
    ----------
    process : calib.calibration.discrepancy.ChannelDiscrepancy
        Its ``amplitude`` τ, ``length`` ℓ, calibration points ``x``, ``weights`` (τ²K + S)⁻¹ e and
        ``inverse`` (τ²K + S)⁻¹.
    x_new : ndarray, shape (n, 3)
    """
    x_new = np.asarray(x_new, float)
    tau2 = float(process.amplitude) ** 2
    k = tau2 * _se_kernel(x_new, process.x, process.length)
    mean = k @ process.weights
    cov = tau2 * _se_kernel(x_new, x_new, process.length) - k @ process.inverse @ k.T
    return mean, 0.5 * (cov + cov.T)


def discrepancy_covariance(process, x_new: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Second-moment matrix D = uuᵀ ∘ (μμᵀ + Σ) of the discrepancy of outputs ``values`` ŷ (n,)
    at ``x_new`` (n, 3) [channel unit²] (module notes), u the process's unit there (|ŷ| for a relative
    process, its constant reference for one in channel units)."""
    mean, cov = discrepancy_moments(process, x_new)
    y = process.unit(values)
    return y[:, None] * (np.outer(mean, mean) + cov) * y[None, :]


def discrepancy_correlation(process, x_new: np.ndarray) -> np.ndarray:
    """The correlation matrix (n, n) of the discrepancy's second moments μμᵀ + Σ at ``x_new`` [-]:
    multiplied by the per-bin σ on both sides it gives :func:`discrepancy_covariance` (zero rows
    where the second moment is zero)."""
    mean, cov = discrepancy_moments(process, x_new)
    m = np.outer(mean, mean) + cov
    d = np.sqrt(np.clip(np.diag(m), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        r = m / np.outer(d, d)
    ok = d > 0
    return np.where(ok[:, None] & ok[None, :], np.clip(r, -1.0, 1.0), 0.0)
