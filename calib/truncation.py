"""Choosing the number of retained θ by estimated predictive error.

Notes
-----
Truncating the SVD is a regularization; how many θ to keep is a bias–variance choice
that the data can make (DESIGN §5). At the current estimate p̂ the model is linearized,
y(p̃) ≈ y(p̂) + G D (p̃ − p̃̂), so in whitened units the residual is r(p̃) ≈ z̃ − M p̃ with the
*pseudo-data* z̃ = r̂ + M p̃̂ (r̂ the whitened residual at p̂, M = R^(−½) G D = U S Vᵀ).
Keeping the first k singular directions gives the fit ẑ_k = U_k U_kᵀ z̃ and hat matrix
H_k = U_k U_kᵀ. Leaving out operating point b (all its channels, the rows R_b) gives,
exactly for this linear problem, the prediction error

.. math::  e_{b,\\mathrm{LOO}}(k) = (I − H_{k,bb})^{-1}\\, (z̃_b − ẑ_{k,b})

(the block form of the leave-one-out identity; Hastie, Tibshirani & Friedman 2009,
§7.10). The criterion is the mean squared whitened leave-one-point-out error per
residual, CV(k) = Σ_b |e_b,LOO(k)|² / n_rows; its expectation is about 1 + (prediction
variance) for a model that is right, and grows with bias (too few θ) and with variance
(too many). The number retained is the smallest k whose CV is within one standard error
(over the operating points) of the minimum: the one-standard-error rule. Points with leverage 1 (a point
that alone determines a direction) make CV infinite for that k, which is correct: its
prediction from the other points is unconstrained.

References
----------
T. Hastie, R. Tibshirani, J. Friedman, The Elements of Statistical Learning, 2nd ed.,
Springer (2009), §7.10.
P.C. Hansen, Rank-Deficient and Discrete Ill-Posed Problems, SIAM (1998), ch. 7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class TruncationCurve:
    """The leave-one-point-out criterion against the number of retained θ.

    Attributes
    ----------
    n_retained : ndarray of int, shape (n_k,)
        k = 0, 1, ..., k_max.
    cv : ndarray, shape (n_k,)
        Mean squared whitened leave-one-point-out prediction error per residual [-].
    fit : ndarray, shape (n_k,)
        Mean squared whitened fit residual per residual [-] (in-sample).
    singular_values : ndarray, shape (n_k,)
        s_k of the last direction kept at each k (inf for k = 0) [1/scale].
    chosen : int
        The fewest θ whose ``cv`` is within one standard error of the minimum.
    cv_se : ndarray, shape (n_k,)
        Standard error of ``cv`` over the operating points [-].
    """

    n_retained: np.ndarray
    cv: np.ndarray
    fit: np.ndarray
    singular_values: np.ndarray
    chosen: int
    cv_se: np.ndarray | None = None

    @property
    def sigma_bar(self) -> float:
        """The threshold σ̄ = 1/s_k* equivalent to the choice [scale units] (inf for k* = 0)."""
        s = self.singular_values[self.chosen]
        return float(1.0 / s) if np.isfinite(s) and s > 0 else float("inf")

    def to_dict(self) -> dict:
        return {"n_retained": self.n_retained, "cv": self.cv, "cv_se": self.cv_se, "fit": self.fit,
                "singular_values": self.singular_values, "chosen": self.chosen, "criterion": "loo_points"}


def loo_curve(M: np.ndarray, z: np.ndarray, n_channels: int, ok: np.ndarray | None = None,
              max_k: int | None = None, rtol: float = 1e-10) -> TruncationCurve:
    """Leave-one-operating-point-out error of the truncated-SVD fit for every k.

    Parameters
    ----------
    M : ndarray, shape (n_points * n_channels, n_params)
        Whitened scaled sensitivities, rows point-major (zero rows at failed points).
    z : ndarray, shape (n_points * n_channels,)
        Whitened pseudo-data z̃ (see the module notes).
    n_channels : int
        Rows per operating point.
    ok : ndarray of bool, shape (n_points,), optional
        Points that take part (default: all).
    max_k : int, optional
        Largest k considered (default: the numerical rank).
    rtol : float
        Singular values below ``rtol`` × s_max count as zero.

    Returns
    -------
    TruncationCurve
    """
    n_rows, n_params = M.shape
    n_points = n_rows // n_channels
    ok = np.ones(n_points, bool) if ok is None else np.asarray(ok, bool)
    rows = np.repeat(ok, n_channels)
    Mo, zo = M[rows], np.asarray(z, float)[rows]
    n_ok = int(ok.sum())
    U, s, _ = np.linalg.svd(Mo, full_matrices=False)
    rank = int(np.count_nonzero(s > rtol * (s[0] if s.size else 0.0)))
    k_max = rank if max_k is None else min(rank, int(max_k))
    Ub = U.reshape(n_ok, n_channels, -1)
    zb = zo.reshape(n_ok, n_channels)
    c = U.T @ zo                                       # coordinates of z̃ on the left singular vectors
    eye = np.eye(n_channels)
    H = np.zeros((n_ok, n_channels, n_channels))
    fitted = np.zeros_like(zb)
    ks, cv, se, fit, sv = [], [], [], [], []
    for k in range(k_max + 1):
        if k > 0:
            u = Ub[:, :, k - 1]
            H += u[:, :, None] * u[:, None, :]
            fitted += u * c[k - 1]
        e = zb - fitted
        A = eye[None] - H
        det = np.linalg.det(A)
        good = np.abs(det) > 1e-10
        loo = np.full_like(e, np.inf)
        if good.any():
            loo[good] = np.linalg.solve(A[good], e[good][..., None])[..., 0]
        ks.append(k)
        per_point = np.sum(loo ** 2, axis=1) / n_channels
        cv.append(float(np.mean(per_point)) if good.all() else float("inf"))
        se.append(float(np.std(per_point, ddof=1) / np.sqrt(n_ok)) if good.all() and n_ok > 1 else float("inf"))
        fit.append(float(np.mean(e ** 2)))
        sv.append(float(s[k - 1]) if k > 0 else float("inf"))
    cv, se = np.array(cv), np.array(se)
    best = int(np.argmin(cv))
    # one-standard-error rule: the fewest θ whose criterion is within one standard error of the
    # minimum (Hastie et al. 2009, §7.10); the curve is flat near its minimum, and there the
    # smaller model predicts as well and is more stable from one linearization to the next
    within = np.flatnonzero(cv <= cv[best] + se[best])
    chosen = int(within[0]) if within.size else best
    return TruncationCurve(np.array(ks), cv, np.array(fit), np.array(sv), chosen, se)
