r"""Choosing the number of retained θ by estimated predictive error.

Notes
-----
Truncating the SVD is a regularization; how many θ to keep is a bias–variance choice
that the data can make (docs/theory.md, Estimation). At the current estimate p̂ the model is linearized,
y(p̃) ≈ y(p̂) + G D (p̃ − p̃̂), so in whitened units the residual is r(p̃) ≈ z̃ − M p̃ with the
*pseudo-data* z̃ = r̂ + M p̃̂ (r̂ the whitened residual at p̂, M = R^(−½) G D = U S Vᵀ).
Keeping the first k singular directions gives the fit ẑ_k = U_k U_kᵀ z̃ and hat matrix
H_k = U_k U_kᵀ. Holding out a set F of operating points (all their channels, rows R_F)
gives, exactly for this linear problem, the prediction error of a fit without them

.. math::  e_F(k) = (I − H_{k,FF})^{-1}\, (z̃_F − ẑ_{k,F})

(the block form of the leave-out identity; Hastie, Tibshirani & Friedman 2009, §7.10),
so K-fold cross-validation costs no refits. The criterion CV(k) is the mean squared
held-out error per residual over K = 10 folds that interleave across the operating
envelope (point j in fold j mod K); its expectation is about 1 + (prediction variance) for a
model that is right, and grows with bias (too few θ) and variance (too many). The number
retained is the fewest k whose CV is within one standard error (over the folds) of the
minimum (the one-standard-error rule; ``one_se=False`` gives argmin CV).

The choice is made among the leading directions that the data determine better than the
stated prior, 1/s_i² <= v_iᵀ P v_i (:func:`prior_limit`): freezing such a direction costs its
prior variance, estimating it costs more. Without that limit the curve of a truth that varies
between the nodes (coverage twin (d), tuning seeds 8300–8329) dipped again at 41–58 θ on 7
of 30 draws (σ(θ) of the last one chosen 26 and 40–53 prior units in the two traced, seeds
8313 and 8312), and those fits ended at χ²/dof 1.1–96 (three
above 20: the estimate left the range where the linearization holds). With the limit the
same seven retain 7–21 θ at χ²/dof 1.5–9.1, and the summed NEES of all 30 is 549 for 507
(band 447–571) instead of 563 for 819 (conservative, 742–900).

Leave-one-point-out (K = number of points) is available but not the default: a point at
the edge of the envelope alone determines some directions (leverage near 1), its leave-out
error explodes and the choice jumps with the linearization point. Measured on the shipped
localization study with every third point held back: the 10-fold choice (33 of 61) came
within 2 % of the best threshold's held-back χ²/dof, leave-one-point-out's (27) was 2.4×
it. Generalized cross-validation was worse still on the wind-tunnel study. The argmin of the
10-fold curve retained more θ than the one-standard-error rule and their NEES over 30 twin
seeds was 918 for 552 degrees of freedom (overconfident); with the rule, 114 for 116 (8 seeds),
but over 30 seeds (``benchmarks/bench_coverage.py``, seeds 5000–5029) 660.6 for 443 (95 % band
387–503), of which the 27 calibrations that ended "converged" 421.4 for 386 (band 333–442;
368.6 with ``scale_by_fit``): one of the three ``not_stable`` ones carries 198 for 19, pulled by
a point with several BEM roots at a section (docs/user_guide/calibration.md). Held-back χ²/dof there (every
third point held back: on the workflows' grids two whole pitch lines, a harder test than the
interleaved folds; on the twin interleaved), the rule against
the best σ̄ of a sweep 0.1–5: wind tunnel (workflow seed) 2.23 against 1.84 (ratio 1.21),
localization stage 2 1.08 against 1.07 (1.015), analytic twin 1.06 against 0.93 (1.13). A
paired standard error (of the difference to the minimum over the folds) and the argmin did
no better on a wind-tunnel draw of the tuning seeds (held-back ratio 1.37 and 1.34 against
0.95 for the rule) and chose the same count on three twin draws.

References
----------
T. Hastie, R. Tibshirani, J. Friedman, The Elements of Statistical Learning, 2nd ed.,
Springer (2009), §7.10.
P.C. Hansen, Rank-Deficient and Discrete Ill-Posed Problems, SIAM (1998), ch. 7.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True, eq=False)
class TruncationCurve:
    """The cross-validation criterion against the number of retained θ.

    Attributes
    ----------
    n_retained : ndarray of int, shape (n_k,)
        k = 0, 1, ..., k_max.
    cv : ndarray, shape (n_k,)
        Mean squared whitened held-out prediction error per residual [-].
    fit : ndarray, shape (n_k,)
        Mean squared whitened fit residual per residual [-] (in-sample).
    singular_values : ndarray, shape (n_k,)
        s_k of the last direction kept at each k (inf for k = 0) [1/scale].
    chosen : int
        k* = argmin ``cv``.
    cv_se : ndarray, shape (n_k,)
        Standard error of ``cv`` over the folds [-].
    per_fold : ndarray, shape (n_k, K), optional
        Mean squared held-out error of each fold [-] (inf where a fold alone determines a
        direction).
    gcv : ndarray, shape (n_k,), optional
        Unused (kept for results that carry it).
    criterion : str
        ``"10-fold"`` (K-fold over operating points) or ``"loo_points"``.
    prior_limit : int, optional
        Most θ the choice may take: the leading directions that the data determine better
        than the stated prior (:func:`prior_limit`); ``None``: no limit.
    """

    n_retained: np.ndarray
    cv: np.ndarray
    fit: np.ndarray
    singular_values: np.ndarray
    chosen: int
    cv_se: np.ndarray | None = None
    gcv: np.ndarray | None = None
    criterion: str = "10-fold"
    per_fold: np.ndarray | None = None
    prior_limit: int | None = None

    @property
    def sigma_bar(self) -> float:
        """The threshold σ̄ = 1/s_k* equivalent to the choice [scale units] (inf for k* = 0)."""
        s = self.singular_values[self.chosen]
        return float(1.0 / s) if np.isfinite(s) and s > 0 else float("inf")

    def to_dict(self) -> dict:
        out = {"n_retained": self.n_retained, "cv": self.cv, "cv_se": self.cv_se, "fit": self.fit,
               "singular_values": self.singular_values, "chosen": self.chosen, "criterion": self.criterion}
        if self.prior_limit is not None:
            out["prior_limit"] = int(self.prior_limit)
        return out


def prior_limit(M: np.ndarray, prior_cov: np.ndarray, ok_rows: np.ndarray | None = None) -> int:
    """Number of leading singular directions the data determine better than the prior.

    Freezing direction v_i at nominal costs the truth's prior variance along it, v_iᵀ P v_i;
    estimating it costs σ(θ_i)² = 1/s_i². A direction with 1/s_i² > v_iᵀ P v_i is better left
    to the prior (its frozen-direction variance is in the bands either way), so the automatic
    choice stops before the first such direction.

    Parameters
    ----------
    M : ndarray, shape (n_rows, n_params)
        Whitened scaled sensitivities.
    prior_cov : ndarray, shape (n_params, n_params)
        Stated prior covariance of the scaled parameters [scale units²].
    ok_rows : ndarray of bool, shape (n_rows,), optional
        Rows that take part (default: all).

    Returns
    -------
    int
        k such that 1/s_i² <= v_iᵀ P v_i for i = 1 … k and not for i = k + 1.
    """
    Mo = M if ok_rows is None else M[np.asarray(ok_rows, bool)]
    _, s, Vt = np.linalg.svd(Mo, full_matrices=False)
    with np.errstate(divide="ignore"):
        data_var = np.where(s > 0, 1.0 / s ** 2, np.inf)
    prior_var = np.einsum("ij,jk,ik->i", Vt, np.asarray(prior_cov, float), Vt)
    worse = np.flatnonzero(data_var > prior_var)
    return int(worse[0]) if worse.size else int(s.size)


def cv_curve(M: np.ndarray, z: np.ndarray, n_channels: int, ok: np.ndarray | None = None,
             n_folds: int | None = 10, max_k: int | None = None, rtol: float = 1e-10,
             one_se: bool = False, max_choice: int | None = None) -> TruncationCurve:
    """K-fold (or leave-one-point-out) prediction error of the truncated-SVD fit for every k.

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
    n_folds : int or None
        K: operating point j (in the order given, counting only ``ok`` points) is in fold
        j mod K, so the folds interleave across the operating envelope. ``None``: leave one
        point out.
    max_k : int, optional
        Largest k considered (default: the numerical rank).
    rtol : float
        Singular values below ``rtol`` × s_max count as zero.
    one_se : bool
        Choose the fewest θ whose criterion is within one standard error (over the folds) of
        the minimum instead of the minimum itself (Hastie et al. 2009, §7.10).
    max_choice : int, optional
        Choose among k <= ``max_choice`` only (the curve still covers every k), e.g.
        :func:`prior_limit`.

    Returns
    -------
    TruncationCurve
        ``cv`` the mean squared whitened held-out error per residual, ``chosen`` its argmin
        (or the one-standard-error choice).
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
    K = n_ok if n_folds is None else max(2, min(int(n_folds), n_ok))
    fold_rows = [np.flatnonzero(np.repeat(np.arange(n_ok) % K == f, n_channels)) for f in range(K)]
    c = U.T @ zo                                       # coordinates of z̃ on the left singular vectors
    ks, cv, se, fit, sv, folds = [], [], [], [], [], []
    for k in range(k_max + 1):
        per_fold, finite = [], True
        for r in fold_rows:
            Uf = U[r, :k]
            e = zo[r] - Uf @ c[:k]
            A = np.eye(r.size) - Uf @ Uf.T
            if k and np.linalg.cond(A) > 1e10:      # the fold alone determines a direction
                finite = False
                break
            held = np.linalg.solve(A, e) if k else e
            per_fold.append(float(held @ held) / r.size)
        resid = zo - U[:, :k] @ c[:k]
        ks.append(k)
        folds.append(per_fold if finite else [float("inf")] * K)
        cv.append(float(np.mean(per_fold)) if finite else float("inf"))
        se.append(float(np.std(per_fold, ddof=1) / np.sqrt(K)) if finite else float("inf"))
        fit.append(float(np.mean(resid ** 2)))
        sv.append(float(s[k - 1]) if k > 0 else float("inf"))
    cv, se = np.array(cv), np.array(se)
    limit = k_max if max_choice is None else max(0, min(int(max_choice), k_max))
    best = int(np.argmin(cv[:limit + 1]))
    chosen = best
    if one_se:
        within = np.flatnonzero(cv[:limit + 1] <= cv[best] + se[best])
        chosen = int(within[0]) if within.size else best
    return TruncationCurve(np.array(ks), cv, np.array(fit), np.array(sv), chosen, se,
                           None, "loo_points" if n_folds is None else f"{K}-fold", np.array(folds),
                           None if max_choice is None else limit)


#: Most linearizations at which the automatic choice chooses the retained count (:class:`AutoTruncation`).
AUTO_CHOICES = 4


class AutoTruncation:
    """The automatic choice of the retained count over a calibration's re-linearizations (``sigma_bar = "auto"``).

    It owns its state: the choices made so far and the count it froze on. The count is chosen
    afresh at each linearization (:func:`cv_curve`, never beyond :func:`prior_limit`) until two
    consecutive choices agree or :data:`AUTO_CHOICES` were made; then the choice with the smallest
    criterion (each on its own linearization's curve) is kept, so that the re-linearization loop
    converges on a subspace instead of chasing a count that moves with the linearization point.

    Parameters
    ----------
    cv_folds, max_retained, one_se
        As :func:`cv_curve`.
    start_at_limit : bool
        The first choice is the prior limit's count (the second start of
        :meth:`calib.calibration.truncated_fit.TruncatedFit.second_start`), the later ones as usual.
    """

    def __init__(self, cv_folds: int, max_retained: int | None, one_se: bool, start_at_limit: bool = False):
        self.cv_folds, self.max_retained, self.one_se = cv_folds, max_retained, one_se
        self.choices: list[tuple[float, int]] = []
        self.frozen: int | None = None
        self.curve: TruncationCurve | None = None
        self._at_limit = start_at_limit

    def restarted_at_limit(self) -> "AutoTruncation":
        """A fresh policy whose first choice is the prior limit's count."""
        return AutoTruncation(self.cv_folds, self.max_retained, self.one_se, start_at_limit=True)

    def choose(self, M: np.ndarray, z: np.ndarray, n_channels: int, ok: np.ndarray, prior_cov: np.ndarray) -> int:
        """The retained count at this linearization (``M``, pseudo-data ``z``, rows ``ok``); the curve is
        kept in :attr:`curve` with that count as its choice."""
        # never more θ than the data determine better than the prior: beyond that the CV curve of a
        # rough truth can dip again at 50+ θ with σ(θ) of tens of prior units, where the estimate
        # leaves the range over which the linearization holds (coverage twin (d))
        limit = prior_limit(M, prior_cov, np.repeat(ok, n_channels))
        curve = cv_curve(M, z, n_channels, ok, self.cv_folds, self.max_retained, one_se=self.one_se,
                         max_choice=limit)
        top = int(curve.n_retained[-1])
        if self._at_limit:
            self._at_limit = False
            curve = replace(curve, chosen=min(limit, top))
        if self.frozen is None:
            self.choices.append((float(curve.cv[curve.chosen]), curve.chosen))
            agree = len(self.choices) >= 2 and self.choices[-1][1] == self.choices[-2][1]
            if agree or len(self.choices) >= AUTO_CHOICES:
                self.frozen = min(self.choices)[1]
                curve = replace(curve, chosen=min(self.frozen, limit, top))
        else:
            curve = replace(curve, chosen=min(self.frozen, limit, top))
        self.curve = curve
        return curve.chosen


def keep_second_start(first: tuple, second: tuple) -> bool:
    """Whether the automatic choice keeps its second start (:meth:`calib.calibration.truncated_fit.TruncatedFit.second_start`).

    Each start is (retained count, criterion at it, its standard error, status). The default
    is the start whose retained set settled (status ``converged``) when only one did, else the
    one with fewer θ, else (equal counts) the first; the other is kept only if its criterion is
    lower than the default's by more than its own standard error. A failed second start, or
    one without a finite criterion, is never kept.
    """
    (k1, cv1, se1, s1), (k2, cv2, se2, s2) = first, second
    if s2 == "failed" or not np.isfinite(cv2):
        return False
    settled1, settled2 = s1 == "converged", s2 == "converged"
    default_second = settled2 if settled1 != settled2 else k2 < k1
    return not cv1 < cv2 - se1 if default_second else cv2 < cv1 - se2
