r"""Is the stated prior what the data say? The prior amplitude by type-II maximum likelihood.

Notes
-----
The bands of the directions the truncation froze are the stated prior's (DESIGN §5), so the
prior's amplitude sets their width. The data carry a check of it. Linearized at the
estimate, the whitened pseudo-data (:mod:`calib.truncation`) are z̃ = Z_f f + Z_n n + ε with
ε ~ N(0, I) (the stated noise), f the correction field and n the other parameters. With
the prior f ~ N(0, τ² K_f) (τ = 1 is the stated prior) and n ~ N(0, K_n), z̃ is Gaussian
with covariance

.. math::  C(τ) = I + Z_n K_n Z_nᵀ + τ² Z_f K_f Z_fᵀ,

and the marginal (type-II) likelihood of τ is ℓ(τ) = −½ (log det C(τ) + z̃ᵀ C(τ)⁻¹ z̃)
(Rasmussen & Williams 2006, §5.4). With B = I + Z_n K_n Z_nᵀ and the singular values λ_i^½ of
G = B^(−½) Z_f K_f^(½) (left vectors u_i), w = B^(−½) z̃:

.. math::  −2ℓ(τ) = \log\det B + Σ_i \log(1 + τ²λ_i) + |w|² − Σ_i (u_iᵀw)² τ²λ_i / (1 + τ²λ_i),

exact for every τ after one SVD. τ̂ maximizes ℓ; the 95 % interval is the profile-
likelihood set 2(ℓ(τ̂) − ℓ(τ)) <= χ²₁(0.95) (Pawitan 2001, §2.6), with lower end 0 when
τ = 0 is inside it and upper end ∞ when the data do not bound it.

When the model can be refined, Z_f are the sensitivities to a field on a grid finer than the
calibration's (:mod:`calib.parametrizations.aliasing`) with the smooth-field prior's
correlation there, so a truth that varies between the nodes as the prior says is not read as
a larger amplitude; otherwise Z_f are the calibration nodes' sensitivities and a truth
outside the span of the hat functions inflates τ̂.

The check assumes the stated noise: noise larger than stated also raises τ̂ (the report says
so next to the χ² test, which measures the noise).

References
----------
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006),
§5.4.
Y. Pawitan, In All Likelihood, Oxford University Press (2001), §2.6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats


@dataclass(frozen=True)
class PriorCheck:
    """The data's estimate of the prior amplitude of the correction field.

    Attributes
    ----------
    amplitude : float
        τ̂, the field's prior standard deviation the data support, in units of the stated one [-].
    lower, upper : float
        Profile-likelihood interval of τ [-] (``upper`` inf when the data do not bound it).
    confidence : float
        Of the interval [-].
    verdict : str
        ``"consistent"`` (1 inside the interval), ``"larger"`` (the data call for a larger prior:
        the frozen directions' bands may be too narrow) or ``"smaller"`` (the bands of the frozen
        directions are wider than the data need).
    between_nodes : bool
        The field between the calibration nodes was part of the check (see the module notes).
    log_lr_at_stated : float
        2(ℓ(τ̂) − ℓ(1)), the likelihood-ratio statistic of the stated prior [-].
    """

    amplitude: float
    lower: float
    upper: float
    confidence: float
    verdict: str
    between_nodes: bool
    log_lr_at_stated: float

    def to_dict(self) -> dict:
        return {"amplitude": self.amplitude, "lower": self.lower, "upper": self.upper,
                "confidence": self.confidence, "verdict": self.verdict, "between_nodes": self.between_nodes,
                "log_lr_at_stated": self.log_lr_at_stated}

    def sentence(self) -> str:
        """One sentence for the report, generated from the numbers."""
        upper = "∞" if not np.isfinite(self.upper) else f"{self.upper:.2g}"
        where = ("with the field between the nodes" if self.between_nodes
                 else "on the calibration nodes only (a truth outside their span raises it)")
        interval = (f"τ̂ = {self.amplitude:.2g} × the stated prior, {100 * self.confidence:.0f} % interval "
                    f"{self.lower:.2g}–{upper}, {where}")
        if self.verdict == "larger":
            return (f"Prior check: the data call for a larger correction field than the stated prior ({interval}); "
                    f"the bands of the directions the data leave to the prior may be too narrow: raise prior_sigma "
                    f"by about {self.amplitude:.2g}, or check that the stated noise is not too small.")
        if self.verdict == "smaller":
            return (f"Prior check: the data call for a smaller correction field than the stated prior ({interval}); "
                    f"the bands of the directions the data leave to the prior are wider than the data need.")
        return f"Prior check: the data are consistent with the stated prior ({interval})."


def _psd_sqrt(K: np.ndarray) -> np.ndarray:
    """L with L Lᵀ = K for a symmetric positive semi-definite K (eigen-decomposition)."""
    w, Q = np.linalg.eigh(0.5 * (K + K.T))
    return Q * np.sqrt(np.clip(w, 0.0, None))


def prior_amplitude(z: np.ndarray, Z_field: np.ndarray, K_field: np.ndarray, Z_other: np.ndarray | None = None,
                    K_other: np.ndarray | None = None, confidence: float = 0.95,
                    between_nodes: bool = False) -> PriorCheck:
    """Type-II maximum-likelihood amplitude of the field's prior and its profile interval.

    Parameters
    ----------
    z : ndarray, shape (n_rows,)
        Whitened pseudo-data z̃ (unit noise variance) [-].
    Z_field : ndarray, shape (n_rows, n_f)
        Whitened sensitivities to the field's values [1/parameter unit].
    K_field : ndarray, shape (n_f, n_f)
        Stated prior covariance of the field's values [parameter unit²].
    Z_other, K_other : ndarray, optional
        The same for the other parameters (prior kept as stated).
    confidence : float
        Of the interval.
    between_nodes : bool
        Recorded in the result: ``Z_field`` are the sensitivities to a field finer than the
        calibration grid.

    Returns
    -------
    PriorCheck
    """
    z = np.asarray(z, float).reshape(-1)
    n = z.size
    if Z_other is not None and Z_other.shape[1]:
        U_n, s_n, _ = np.linalg.svd(np.asarray(Z_other, float) @ _psd_sqrt(np.asarray(K_other, float)),
                                    full_matrices=False)
        shrink = 1.0 - 1.0 / np.sqrt(1.0 + s_n ** 2)
        logdet_b = float(np.sum(np.log1p(s_n ** 2)))

        def b_half_inv(X):
            return X - U_n @ (shrink[:, None] * (U_n.T @ X)) if X.ndim == 2 else X - U_n @ (shrink * (U_n.T @ X))
    else:
        logdet_b = 0.0

        def b_half_inv(X):
            return X
    G = b_half_inv(np.asarray(Z_field, float) @ _psd_sqrt(np.asarray(K_field, float)))
    w = b_half_inv(z)
    U, s, _ = np.linalg.svd(G, full_matrices=False) if G.size else (np.zeros((n, 0)), np.zeros(0), None)
    lam, c2, w2 = s ** 2, (U.T @ w) ** 2, float(w @ w)

    def minus2l(log_tau):
        """−2ℓ at log τ (scalar or array) [-]."""
        t2l = np.exp(2.0 * np.asarray(log_tau, float))[..., None] * lam
        return logdet_b + np.sum(np.log1p(t2l), -1) + w2 - np.sum(c2 * t2l / (1.0 + t2l), -1)

    # a log grid, then a bounded refinement around its best point
    grid = np.linspace(np.log(1e-3), np.log(1e3), 121)
    vals = minus2l(grid)
    i = int(np.argmin(vals))
    opt = optimize.minimize_scalar(minus2l, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]),
                                   method="bounded", options={"xatol": 1e-6})
    best_log, best = (float(opt.x), float(opt.fun)) if opt.fun <= vals[i] else (float(grid[i]), float(vals[i]))
    at_zero = logdet_b + w2                                          # τ = 0 exactly
    if at_zero < best:
        best_log, best = -np.inf, at_zero
    crit = float(stats.chi2.ppf(confidence, 1))

    def excess(log_tau):
        return float(minus2l(log_tau)) - best - crit

    start = best_log if np.isfinite(best_log) else np.log(1e-12)

    def crossing(points):
        """τ where the excess first turns positive along ``points`` (log τ moving away from τ̂),
        refined by bisection against the point before; None if it never does."""
        j = np.flatnonzero(minus2l(points) - best - crit > 0)
        if not j.size:
            return None
        prev = start if j[0] == 0 else points[j[0] - 1]
        return float(np.exp(optimize.brentq(excess, min(prev, points[j[0]]), max(prev, points[j[0]]))))

    lower = 0.0 if at_zero - best <= crit else (crossing(grid[grid < best_log][::-1]) or 0.0)
    upper = crossing(grid[grid > start])
    upper = float("inf") if upper is None else upper
    tau_hat = float(np.exp(best_log))
    at_stated = float(minus2l(0.0)) - best
    verdict = "consistent" if lower <= 1.0 <= upper else ("larger" if lower > 1.0 else "smaller")
    return PriorCheck(tau_hat, lower, upper, float(confidence), verdict, bool(between_nodes), float(at_stated))
