r"""Is the stated prior what the data say? The prior amplitude by type-II maximum likelihood.

Notes
-----
The bands of the directions the truncation froze are the stated prior's (docs/theory.md, Uncertainty), so the
prior's amplitude sets their width. The data carry a check of it. Linearized at a point
p̃ (the MAP under the stated prior, see below), the whitened pseudo-data
(:mod:`calib.calibration.truncation`) are z̃ = Z_f f + Z_n n + ε with ε ~ N(0, I) (the stated noise),
f the correction field and n the other parameters. With the prior f ~ N(0, τ² K_f) (τ = 1
is the stated prior) and n ~ N(0, K_n), z̃ is Gaussian with covariance

.. math::  C(τ) = I + Z_n K_n Z_nᵀ + τ² Z_f K_f Z_fᵀ,

and the marginal (type-II) likelihood of τ is ℓ(τ) = −½ (log det C(τ) + z̃ᵀ C(τ)⁻¹ z̃)
(Rasmussen & Williams 2006, §5.4). With B = I + Z_n K_n Z_nᵀ and the singular values λ_i^½ of
G = B^(−½) Z_f K_f^(½) (left vectors u_i), w = B^(−½) z̃:

.. math::  −2ℓ(τ) = \log\det B + Σ_i \log(1 + τ²λ_i) + |w|² − Σ_i (u_iᵀw)² τ²λ_i / (1 + τ²λ_i),

exact for every τ after one SVD. τ̂ maximizes ℓ; the 95 % interval is the profile-
likelihood set 2(ℓ(τ̂) − ℓ(τ)) <= χ²₁(0.95) (Pawitan 2001, likelihood intervals), with lower
end 0 when τ = 0 is inside it and upper end ∞ when the data do not bound it.

When the model can be refined, Z_f are the sensitivities to a field on a grid finer than the
calibration's (:mod:`calib.parametrizations.aliasing`) with the smooth-field prior's
correlation there, so a truth that varies between the nodes as the prior says is not read as
a larger amplitude; otherwise Z_f are the calibration nodes' sensitivities and a truth
outside the span of the hat functions inflates τ̂.

The check assumes the stated noise and a model linear between the estimate and the truth:
noise larger than stated raises τ̂, and so does a truncated fit far from the truth in its
frozen directions where the model is not linear (its χ²/dof after is then well above 1), which
is why the check linearizes at the MAP under the stated prior (:func:`map_point`). On the
coverage twins (``benchmarks/bench_coverage.py``, tuning seeds 8300–8329) truths drawn from the
very prior the check assumes (twin d) gave an interval holding 1 in 26 of 30 runs (25 when
linearized at the truncated estimate); two of the three called "larger" had χ²/dof after 5.7
and 15.7. Truths drawn at the calibration nodes (twin c, piecewise linear between them, so with
less fine structure than the prior) were called "smaller" 12 times and "larger" once.

References
----------
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006),
§5.4.
Y. Pawitan, In All Likelihood: Statistical Modelling and Inference Using Likelihood, Oxford
University Press (2001).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

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
    chi2_map, chi2_estimate : float or None
        χ² of the fit at the point the check linearizes (the MAP under the stated prior,
        :func:`map_point`) and at the calibration's estimate [-]; None when not recorded.
    map_iterations : int or None
        Gauss–Newton steps to the MAP.
    map_converged : bool or None
        Whether they met the tolerance (else the check is at the last step).
    """

    amplitude: float
    lower: float
    upper: float
    confidence: float
    verdict: str
    between_nodes: bool
    log_lr_at_stated: float
    chi2_map: float | None = None
    chi2_estimate: float | None = None
    map_iterations: int | None = None
    map_converged: bool | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    def sentence(self) -> str:
        """One sentence for the report, generated from the numbers."""
        upper = "∞" if not np.isfinite(self.upper) else f"{self.upper:.2g}"
        where = ("with the field between the nodes" if self.between_nodes
                 else "on the calibration nodes only (a truth outside their span raises it)")
        interval = (f"τ̂ = {self.amplitude:.2g} × the stated prior, {100 * self.confidence:.0f} % interval "
                    f"{self.lower:.2g}–{upper}, {where}")
        if self.chi2_map is not None and self.chi2_estimate is not None:
            interval += (f"; linearized at the estimate under the stated prior with every direction free, whose "
                         f"χ² is {self.chi2_map:.4g} against {self.chi2_estimate:.4g} at the calibration's estimate"
                         + ("" if self.map_converged in (None, True) else
                            f", after {self.map_iterations} Gauss–Newton steps that did not meet the tolerance"))
        if self.verdict == "larger":
            return (f"Prior check: the data call for a larger correction field than the stated prior ({interval}); "
                    f"the bands of the directions the data leave to the prior may be too narrow: raise prior_sigma "
                    f"by about {self.amplitude:.2g}. A stated noise that is too small raises τ̂ as well, and so "
                    f"does a fit that leaves structure in the residuals where the model is not linear between the "
                    f"estimate and the truth (χ²/dof after well above 1, few θ retained).")
        if self.verdict == "smaller":
            return (f"Prior check: the data call for a smaller correction field than the stated prior ({interval}); "
                    f"the bands of the directions the data leave to the prior are wider than the data need.")
        return f"Prior check: the data are consistent with the stated prior ({interval})."


def psd_sqrt(K: np.ndarray) -> np.ndarray:
    """L with L Lᵀ = K for a symmetric positive semi-definite K (eigen-decomposition)."""
    w, Q = np.linalg.eigh(0.5 * (K + K.T))
    return Q * np.sqrt(np.clip(w, 0.0, None))


#: The log τ grid the likelihood is first scanned on (τ from 10⁻³ to 10³) [-].
_LOG_TAU_GRID = np.linspace(np.log(1e-3), np.log(1e3), 121)


def prior_amplitude(z: np.ndarray, Z_field: np.ndarray, K_field: np.ndarray | None, Z_other: np.ndarray | None = None,
                    K_other: np.ndarray | None = None, confidence: float = 0.95,
                    between_nodes: bool = False, field_sqrt: np.ndarray | None = None) -> PriorCheck:
    """Type-II maximum-likelihood amplitude of the field's prior and its profile interval.

    Parameters
    ----------
    z : ndarray, shape (n_rows,)
        Whitened pseudo-data z̃ (unit noise variance) [-].
    Z_field : ndarray, shape (n_rows, n_f)
        Whitened sensitivities to the field's values [1/parameter unit].
    K_field : ndarray, shape (n_f, n_f), or None
        Stated prior covariance of the field's values [parameter unit²] (None: ``field_sqrt``
        is given).
    Z_other, K_other : ndarray, optional
        The same for the other parameters (prior kept as stated).
    confidence : float
        Of the interval.
    between_nodes : bool
        Recorded in the result: ``Z_field`` are the sensitivities to a field finer than the
        calibration grid.
    field_sqrt : ndarray, shape (n_f, n_r), optional
        L with L Lᵀ = ``K_field``, when the caller has it cheaper than an eigen-decomposition.

    Returns
    -------
    PriorCheck
    """
    z = np.asarray(z, float).reshape(-1)
    L_f = psd_sqrt(np.asarray(K_field, float)) if field_sqrt is None else np.asarray(field_sqrt, float)
    minus2l, at_zero = _marginal_likelihood(z, np.asarray(Z_field, float) @ L_f, Z_other, K_other)
    best_log, best = _maximum(minus2l, at_zero)
    crit = float(stats.chi2.ppf(confidence, 1))
    lower, upper = _profile_interval(minus2l, best_log, best, at_zero, crit)
    tau_hat = float(np.exp(best_log))
    at_stated = float(minus2l(0.0)) - best
    verdict = "consistent" if lower <= 1.0 <= upper else ("larger" if lower > 1.0 else "smaller")
    return PriorCheck(tau_hat, lower, upper, float(confidence), verdict, bool(between_nodes), float(at_stated))


def _other_whitening(Z_other: np.ndarray | None, K_other: np.ndarray | None):
    """B^(−½) as a function of a matrix, and log det B, for B = I + Z_n K_n Zₙᵀ (module notes).

    Parameters
    ----------
    Z_other, K_other : ndarray or None
        Whitened sensitivities to the other parameters and their prior covariance; without
        them B = I.

    Returns
    -------
    b_half_inv : callable
        X ↦ B^(−½) X.
    logdet_b : float
        log det B [-].
    """
    if Z_other is not None and Z_other.shape[1]:
        U_n, s_n, _ = np.linalg.svd(np.asarray(Z_other, float) @ psd_sqrt(np.asarray(K_other, float)),
                                    full_matrices=False)
        shrink = 1.0 - 1.0 / np.sqrt(1.0 + s_n ** 2)
        logdet_b = float(np.sum(np.log1p(s_n ** 2)))

        def b_half_inv(X):
            return X - U_n @ (shrink[:, None] * (U_n.T @ X))
    else:
        logdet_b = 0.0

        def b_half_inv(X):
            return X
    return b_half_inv, logdet_b


def _marginal_likelihood(z: np.ndarray, field_scaled: np.ndarray, Z_other: np.ndarray | None,
                         K_other: np.ndarray | None):
    """−2ℓ as a function of log τ, exact after one SVD (module notes), and its value at τ = 0.

    Parameters
    ----------
    z : ndarray, shape (n_rows,)
        Whitened pseudo-data [-].
    field_scaled : ndarray, shape (n_rows, n_r)
        Z_f K_f^(½) [-].
    Z_other, K_other : ndarray or None
        As :func:`prior_amplitude`.

    Returns
    -------
    minus2l : callable
        log τ (scalar or array) ↦ −2ℓ [-].
    at_zero : float
        −2ℓ at τ = 0 exactly [-].
    """
    b_half_inv, logdet_b = _other_whitening(Z_other, K_other)
    G = b_half_inv(field_scaled)
    w = b_half_inv(z[:, None])[:, 0]
    U, s, _ = np.linalg.svd(G, full_matrices=False) if G.size else (np.zeros((z.size, 0)), np.zeros(0), None)
    lam, c2, w2 = s ** 2, (U.T @ w) ** 2, float(w @ w)

    def minus2l(log_tau):
        """−2ℓ at log τ (scalar or array) [-]."""
        t2l = np.exp(2.0 * np.asarray(log_tau, float))[..., None] * lam
        return logdet_b + np.sum(np.log1p(t2l), -1) + w2 - np.sum(c2 * t2l / (1.0 + t2l), -1)

    return minus2l, logdet_b + w2


def _maximum(minus2l, at_zero: float) -> tuple[float, float]:
    """(log τ̂, −2ℓ there): the best of a log grid, refined by a bounded search around it; log τ̂ is
    −inf when τ = 0 (−2ℓ = ``at_zero``) does better."""
    grid = _LOG_TAU_GRID
    vals = minus2l(grid)
    i = int(np.argmin(vals))
    opt = optimize.minimize_scalar(minus2l, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]),
                                   method="bounded", options={"xatol": 1e-6})
    best_log, best = (float(opt.x), float(opt.fun)) if opt.fun <= vals[i] else (float(grid[i]), float(vals[i]))
    if at_zero < best:
        best_log, best = -np.inf, at_zero
    return best_log, best


def _profile_interval(minus2l, best_log: float, best: float, at_zero: float, crit: float) -> tuple[float, float]:
    """The profile-likelihood interval {τ : −2ℓ(τ) − ``best`` <= ``crit``} around log τ̂ = ``best_log``.

    Returns
    -------
    lower, upper : float
        Its ends [-]: ``lower`` 0 when τ = 0 (−2ℓ = ``at_zero``) is inside it, ``upper`` inf when
        the data do not bound it.
    """
    grid = _LOG_TAU_GRID

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
    return lower, float("inf") if upper is None else upper


@dataclass(frozen=True, eq=False)
class MapPoint:
    """Where the prior check linearizes: the maximum a posteriori estimate under the stated prior.

    Attributes
    ----------
    x : ndarray, shape (n_params,)
        Scaled parameters p̃ at the MAP [scale units].
    residual : ndarray, shape (n_rows,)
        Whitened residuals there (0 on rows that did not converge) [-].
    ok_rows : ndarray of bool, shape (n_rows,)
    M : ndarray, shape (n_rows, n_params)
        Whitened scaled sensitivities there.
    iterations : int
        Gauss–Newton steps taken.
    converged : bool
        The relative decrease of the cost fell below the tolerance.
    """

    x: np.ndarray
    residual: np.ndarray
    ok_rows: np.ndarray
    M: np.ndarray
    iterations: int
    converged: bool

    @property
    def chi2(self) -> float:
        """Σ r² over the converged rows [-]."""
        return float(np.sum(self.residual[self.ok_rows] ** 2))


def map_point(linearize_at, x0: np.ndarray, prior_cov: np.ndarray, max_iterations: int = 10,
              rtol: float = 1e-4, evaluate_at=None) -> MapPoint:
    """Gauss–Newton for min ½|r(x)|² + ½ xᵀP⁻¹x over the scaled parameters, from ``x0``.

    The truncated estimate leaves the frozen directions at nominal; where the truth is large
    there and the model is not linear, the pseudo-data linearized at that estimate carry the
    model's curvature, which the check would read as field amplitude (twin d, tuning seed 8319:
    7 θ retained, χ²/dof after 9.1, τ̂ = 6.3; with σ̄ = 1, 26 θ, τ̂ = 0.90). The MAP under the
    stated prior is the point of the Laplace approximation of the marginal likelihood at τ = 1
    (Rasmussen & Williams 2006, ch. 3, on the Laplace approximation). Steps are in u = L⁺x
    (P = L Lᵀ), (AᵀA + I)Δu = Aᵀr − u with A = M L, halved (at most 6 times) until the cost
    falls without losing converged rows.

    Parameters
    ----------
    linearize_at : callable
        x ↦ (x_used, residual, ok_rows, M): the model linearized at x within the parameter
        bounds (x_used the point after the bounds).
    x0 : ndarray
        Start (the truncated estimate) [scale units].
    prior_cov : ndarray
        Stated prior covariance P of the scaled parameters.
    max_iterations : int
        Gauss–Newton steps at most.
    rtol : float
        Stop when a step lowers the cost by less than this fraction.
    evaluate_at : callable, optional
        x ↦ (x_used, residual, ok_rows) without sensitivities, to try a step before paying for
        a Jacobian (default: ``linearize_at``).

    Returns
    -------
    MapPoint
    """
    L = psd_sqrt(np.asarray(prior_cov, float))
    evaluate_at = evaluate_at or (lambda x: linearize_at(x)[:3])

    def cost_of(x, r, ok):
        u = np.linalg.lstsq(L, x, rcond=None)[0]
        return u, 0.5 * float(np.sum(r[ok] ** 2) + u @ u)

    x, r, ok, M = linearize_at(np.asarray(x0, float))
    u, cost = cost_of(x, r, ok)
    converged, it = False, 0
    for it in range(1, max_iterations + 1):
        A = np.where(ok[:, None], M, 0.0) @ L
        du = np.linalg.solve(A.T @ A + np.eye(L.shape[1]), A.T @ np.where(ok, r, 0.0) - u)
        step, accepted = 1.0, None
        for _ in range(7):
            xt, rt, okt = evaluate_at(x + step * (L @ du))
            _, ct = cost_of(xt, rt, okt)
            if ct < cost and okt.sum() >= ok.sum():
                accepted = (xt, ct)
                break
            step *= 0.5
        if accepted is None:
            converged = True            # no step lowers the cost: a (local) minimum along Gauss–Newton
            it -= 1
            break
        old = cost
        x, r, ok, M = linearize_at(accepted[0])
        u, cost = cost_of(x, r, ok)
        if old - cost <= rtol * max(old, 1.0):
            converged = True
            break
    return MapPoint(x, r, ok, M, it, converged)
