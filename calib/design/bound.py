r"""An upper bound on the log det any design of N candidates can reach: the continuous relaxation.

Every exact design of N distinct candidates is a weight vector w ∈ {0, 1}^{n_c} with Σ w = N, and
f(w) = log det(I + Σ_j w_j H_jᵀH_j) is concave in w (Boyd & Vandenberghe 2004, § 7.5.2). Over the
relaxed set W_N = {0 ≤ w ≤ 1, Σ w = N} the maximum f* bounds every exact design's, and at any w ∈ W_N
concavity gives the certificate

.. math::  f^* \le f(w) + \max_{v \in W_N} \nabla f(w)ᵀ (v - w),\qquad
           \partial f / \partial w_j = \mathrm{tr}(H_j A(w)^{-1} H_jᵀ),

the maximum over v putting weight 1 on the N largest gradients. Frank–Wolfe iterations with an exact
line search (the eigenvalues of the step along v − w) tighten w; the bound is the smallest certificate
seen. A target such as "90 % of the full set's log det with 25 % of the points" that lies above the
bound is out of reach of every design, not only of the greedy one.

References
----------
S. Boyd, L. Vandenberghe, Convex Optimization, Cambridge University Press (2004), § 7.5.
M. Frank, P. Wolfe, An algorithm for quadratic programming, Naval Res. Logist. Q. 3 (1956) 95-110.
"""

from __future__ import annotations

import numpy as np

__all__ = ["relaxed_logdet_bound"]


def _fisher(H: np.ndarray, w: np.ndarray) -> np.ndarray:
    return np.einsum("j,jmi,jmk->ik", w, H, H)


def _step(A: np.ndarray, D: np.ndarray) -> float:
    """argmax over γ ∈ [0, 1] of log det(A + γ D) (concave in γ): bisection on Σ μ_i/(1 + γ μ_i) = 0,
    μ the eigenvalues of A^{-½} D A^{-½}."""
    Lc = np.linalg.cholesky(A)
    X = np.linalg.solve(Lc, np.linalg.solve(Lc, D).T)
    mu = np.linalg.eigvalsh(0.5 * (X + X.T))

    def slope(g):
        return float(np.sum(mu / (1.0 + g * mu)))
    if slope(1.0) >= 0:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if slope(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def relaxed_logdet_bound(H: np.ndarray, n_points: int, start=None, iterations: int = 200,
                         tolerance: float = 1e-3) -> dict:
    """An upper bound on log det(I + Σ_{j∈ξ} H_jᵀH_j) over every design ξ of ``n_points`` distinct candidates.

    Parameters
    ----------
    H : ndarray, shape (n_candidates, m, n)
        The candidates' prior-whitened blocks (:mod:`calib.design.criteria`).
    n_points : int
        Points in the design, 1 ≤ n_points ≤ n_candidates.
    start : sequence of int, optional
        An exact design to start from (e.g. the greedy one); default equal weights.
    iterations : int
        Frank–Wolfe iterations at most.
    tolerance : float
        Stop when the certificate is within this of the relaxed value [-].

    Returns
    -------
    dict
        ``bound`` (the certificate, ≥ every exact design's log det), ``relaxed`` (the best relaxed value
        found, ≤ f*), ``iterations`` [-].
    """
    n_c = H.shape[0]
    if not 1 <= n_points <= n_c:
        raise ValueError(f"n_points must be 1..{n_c}, got {n_points}")
    n = H.shape[-1]
    if start is None:
        w = np.full(n_c, n_points / n_c)
    else:
        w = np.zeros(n_c)
        w[np.asarray(start, int)] = 1.0
    best_bound, value = np.inf, -np.inf
    k = 0
    for k in range(1, iterations + 1):
        A = np.eye(n) + _fisher(H, w)
        value = float(np.linalg.slogdet(A)[1])
        G = H @ np.linalg.inv(A)
        grad = np.einsum("jmi,jmi->j", G, H)
        top = np.argsort(grad)[::-1][:n_points]
        v = np.zeros(n_c)
        v[top] = 1.0
        best_bound = min(best_bound, value + float(grad @ (v - w)))
        if best_bound - value <= tolerance:
            break
        d = v - w
        w = np.clip(w + _step(A, _fisher(H, d)) * d, 0.0, 1.0)
    return {"bound": best_bound, "relaxed": value, "iterations": k}
