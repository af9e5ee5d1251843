"""Retained directions that an operating point near a fold of the BEM equations determines
(:func:`fold_dominated_directions`): their σ(θ) holds only on a narrow ridge, so the
calibration states them with their prior variance (docs/user_guide/calibration.md).
"""

from __future__ import annotations

import numpy as np

FOLD_SHARE = 0.5
"""A retained direction whose information comes more than this fraction from points with
several roots of the model's equations is stated with its prior variance
(:func:`fold_dominated_directions`) [-]."""


def fold_dominated_directions(M: np.ndarray, n_channels: int, V_retained: np.ndarray, s_retained: np.ndarray,
                              flagged: np.ndarray, ok: np.ndarray | None = None,
                              share: float = FOLD_SHARE) -> list[dict]:
    r"""Retained directions that a point with several roots of the model's equations determines.

    The information of the retained θ_i is s_i² = ‖M v_i‖², a sum over operating points of
    ‖M_j v_i‖². A point where the BEM residual has several roots at a section
    (:mod:`calib.bem.multiple_roots`) sits near a fold of that residual: the root the solver
    keeps can vanish or jump to another branch under a small change of the polar, and near
    the fold its sensitivity dφ/dp ∝ 1/R'(φ) grows without bound. A direction that such a
    point alone determines then has a σ(θ_i) = 1/s_i that holds only on a ridge far narrower
    than the model's range of validity, and the likelihood can have another mode along it.
    On coverage twin (d), tuning seed 8301, with the minimum of the cross-validated curve
    (24 θ), the point at λ = 2, pitch −2° (several roots at the tip) carried 99.5 % of the
    leading direction (s_1 = 609 where the next was 64, its whitened sensitivity 608 against
    at most 33 at the other points): the estimate sat 8.9 stated σ from the truth along it,
    and that run's NEES was 175.8 for 24. Points with several roots that are not near a fold
    carried at most 38 % of any retained direction in the eight runs of the same twin (seeds
    8300–8329, default truncation) that had such points. Adding the prior variance widens the
    direction the point determines; it does not repair the rest of a fit the point pulled (that
    run's NEES went to 163.6, docs/user_guide/calibration.md).

    Parameters
    ----------
    M : ndarray, shape (n_points * n_channels, n_params)
        Whitened scaled sensitivities at the estimate, rows point-major.
    n_channels : int
        Rows per operating point.
    V_retained : ndarray, shape (n_params, k)
        Retained right singular vectors of ``M``.
    s_retained : ndarray, shape (k,)
        Their singular values [1/scale units].
    flagged : ndarray of bool, shape (n_points,)
        Points where the model reported several roots.
    ok : ndarray of bool, shape (n_points,), optional
        Points that take part (default: all).
    share : float
        Fraction of a direction's information above which it is reported [-].

    Returns
    -------
    list of dict
        One entry per (point, direction) with ``point`` (0-based row of the conditions),
        ``theta`` (1-based index of the retained θ), ``share`` (of s_i²) and
        ``sensitivity_ratio`` (the point's ‖M_j‖ over the median of the other points).
    """
    flagged = np.asarray(flagged, bool)
    if V_retained.shape[1] == 0 or not flagged.any():
        return []
    n_points = M.shape[0] // n_channels
    ok = np.ones(n_points, bool) if ok is None else np.asarray(ok, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        U = (M @ V_retained) / np.asarray(s_retained, float)
    energy = (np.nan_to_num(U) ** 2).reshape(n_points, n_channels, -1).sum(axis=1)   # (points, k)
    norms = np.linalg.norm(M.reshape(n_points, n_channels, -1), axis=(1, 2))
    out = []
    for j in np.flatnonzero(flagged & ok):
        others = norms[ok & (np.arange(n_points) != j)]
        ref = float(np.median(others)) if others.size else float("nan")
        for i in np.flatnonzero(energy[j] > share):
            out.append({"point": int(j), "theta": int(i) + 1, "share": float(energy[j, i]),
                        "sensitivity_ratio": float(norms[j] / ref) if ref > 0 else float("inf")})
    return out
