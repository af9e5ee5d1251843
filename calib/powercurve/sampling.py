"""The sampling (frequentist) covariance of a MAP estimate beside its posterior (Laplace) covariance.

The posterior covariance of a MAP estimate, C = (H + P⁻¹)⁻¹ (H = GᵀR⁻¹G the data's information, P
the prior; :func:`calib.calibration.uncertainty.laplace_covariance`), says how far the truth may lie from
the estimate for a truth drawn from the prior. The spread of the estimate itself over repeated noise,
at one fixed truth, is smaller: the MAP is p̂ = p₀ + K r̃ to first order (K the gain,
``result.uncertainty.gain``, r̃ the whitened data), so Cov(p̂) = K E[r̃r̃ᵀ] Kᵀ = k K Kᵀ with k the
noise-variance factor the Laplace covariance also uses (``fit_scale``); in closed form
K Kᵀ = (H + P⁻¹)⁻¹ H (H + P⁻¹)⁻¹, the sandwich. Along a direction of information s² in the
prior-whitened coordinates the posterior variance is 1/(1 + s²) and the sampling variance
s²/(1 + s²)²: smaller by the factor s²/(1 + s²) = 1 − b (b the posterior/prior variance ratio of
:func:`calib.powercurve.field.prior_split`). The difference is the prior's shrinkage, a bias at a
fixed truth, which the posterior interval carries as width (Bayesian) and the sampling interval
does not (frequentist). Neither is wrong; they answer different questions, and the AEP table gives
both (:func:`calib.powercurve.budget.aep_rows`).

References
----------
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006), §2.2 and §3.4.
L. Wasserman, All of Statistics, Springer (2004), §11.9 (frequentist coverage of Bayesian intervals).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

__all__ = ["interval_coverage", "sampling_covariance"]


def sampling_covariance(result, fit_scale: float | None = None) -> np.ndarray | None:
    """Cov(p̂) over repeated noise at a fixed truth, linearized: k D K Kᵀ D [parameter units²].

    Parameters
    ----------
    result : CalibrationResult
        A MAP result: ``uncertainty.gain`` (n, m·c) [scale units per whitened residual],
        ``uncertainty.fit_scale`` k [-] and ``estimate.scale`` D (n,) [parameter units per scale unit].
    fit_scale : float, optional
        k in place of the recorded one: k' where a model discrepancy carries the misfit
        (:func:`calib.calibration.discrepancy_scale.discrepancy_aware_covariance`), whose fixed part is a
        bias at a fixed truth, not noise [-].

    Returns
    -------
    ndarray, shape (n, n) or None
        None where the result records no gain (truncated estimator, no field term).
    """
    unc = result.uncertainty
    K = np.asarray(unc.gain, float)
    d = np.asarray(result.estimate.scale, float)
    if K.ndim != 2 or not K.size or K.shape[0] != d.size:
        return None
    KD = d[:, None] * K
    return float(unc.fit_scale if fit_scale is None else fit_scale) * (KD @ KD.T)


def interval_coverage(halfwidth, bias, sd) -> np.ndarray:
    """Probability that est ± ``halfwidth`` holds the truth when est − truth ~ N(``bias``, ``sd``²) [-].

    Φ((h − b)/s) − Φ((−h − b)/s): the frequentist coverage of a fixed-width interval at a fixed truth
    (Wasserman 2004, §11.9). ``halfwidth``, ``bias`` and ``sd`` in one unit, broadcast together."""
    h, b, s = (np.asarray(x, float) for x in (halfwidth, bias, sd))
    s = np.maximum(s, 1e-300)
    return norm.cdf((h - b) / s) - norm.cdf((-h - b) / s)
