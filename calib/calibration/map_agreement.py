"""The MAP estimate's self-check against the data alone: :func:`map_ml_agreement`.

A prior can make a MAP estimate confidently wrong in two ways a status cannot show:

1. **It fixes what the data determine.** A prior that is (near-)singular along a direction the
   data determine (an outer product σσᵀ says that all parameters move together; a ``prior_std``
   near zero says that one does not move) keeps the estimate at the prior mean there whatever the
   data say. Seen as a loss of rank: the prior-whitened sensitivities M L have fewer directions
   than the sensitivities M.
2. **It pulls where the data dominate.** Along a direction of the prior-whitened SVD
   M L = U S Wᵀ with s_i ≫ 1 the data outweigh the prior, and the MAP and the maximum-likelihood
   estimates must agree within the ML σ (1/s_i in the whitened coordinate). The Gauss–Newton ML
   step from the MAP along that direction, in ML standard deviations, is z_i = |u_iᵀ r| (r the
   whitened residual at the MAP). At a converged MAP it equals |c_i|/s_i, c_i the estimate's
   whitened coordinate, so it is small unless the estimator stopped short or the prior is wrong.

Both are computed at the estimate from the sensitivities the estimator already has: no model call.
Parameters at a bound are held there; the check is made on the others, under the prior
conditioned on the held ones (Rasmussen & Williams 2006, §A.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.checks.prior_check import psd_sqrt

#: Directions with prior-whitened s_i at or above this are "data-dominated" (s ≫ 1): there the
#: prior's share of the posterior precision is at most 1/(1 + s²) ≈ 1 %.
DOMINANT_S = 10.0

#: The MAP and ML estimates agree when the ML step from the MAP is within this many ML σ.
AGREEMENT_Z = 1.0

#: The prior fixes a direction when its σ along it is below this [scale units], or this fraction of
#: its largest σ (round-off of a flat prior): numerically zero. A stated ``prior_std`` is far above.
FIXED_SD = 1e-6

#: Numerical rank of the sensitivities: singular values above this fraction of the largest.
RANK_RTOL = 1e-6

#: How close to a bound (in scale units) a parameter counts as held there.
AT_BOUND = 1e-6


@dataclass(frozen=True)
class MapAgreement:
    """The MAP's self-check (:func:`map_ml_agreement`).

    Attributes
    ----------
    n_dominant : int
        Directions where the data dominate the prior (s_i ≥ ``DOMINANT_S``).
    max_z : float
        The largest ML step from the MAP over those directions [ML σ] (0 without any).
    disagree : list of str
        Parameters whose ML step from the MAP exceeds ``AGREEMENT_Z`` of its σ, the largest first
        (at most ``MAX_NAMED``; empty when the two agree).
    n_fixed : int
        Directions the data see that the prior fixes: the rank the prior-whitened sensitivities
        M L lose against M.
    fixed : list of str
        Parameters those directions move most.
    n_data : int
        The numerical rank of M over the parameters not at a bound.
    """

    n_dominant: int
    max_z: float
    disagree: list = field(default_factory=list)
    n_fixed: int = 0
    fixed: list = field(default_factory=list)
    n_data: int = 0

    @property
    def ok(self) -> bool:
        return not self.disagree and not self.n_fixed

    def sentence(self) -> str:
        """One plain statement for the result's checks and the report."""
        parts = []
        if self.n_fixed:
            parts.append(
                f"WARNING: the stated prior fixes {self.n_fixed} of the {self.n_data} direction(s) the data see "
                f"(its σ there is numerically zero: the prior-whitened sensitivities have rank "
                f"{self.n_data - self.n_fixed} where the sensitivities have {self.n_data}), so the estimate of {', '.join(self.fixed)} there is the prior's, not the data's: a prior "
                "stated with (near-)perfect correlations, or a prior_std near zero")
        if self.disagree:
            parts.append(
                f"WARNING: where the data dominate the prior (s ≥ {DOMINANT_S:g}) the MAP and the ML estimates differ by "
                f"up to {self.max_z:.3g} ML σ (they must agree within {AGREEMENT_Z:g}); parameters "
                f"{', '.join(self.disagree)}: the estimator stopped short of the posterior's maximum or the prior "
                "is not the one stated")
        if parts:
            return "; ".join(parts)
        if self.n_dominant == 0:
            return (f"MAP and ML agree: no direction where the data dominate the prior (s ≥ {DOMINANT_S:g}) to "
                    f"compare; the prior keeps the rank of all {self.n_data} direction(s) the data see")
        return (f"MAP and ML agree within {self.max_z:.2g} ML σ along the {self.n_dominant} direction(s) where the "
                f"data dominate the prior (s ≥ {DOMINANT_S:g}); the prior keeps the rank of all {self.n_data} "
                "direction(s) the data see")


#: At most this many parameters are named, the largest disagreement first.
MAX_NAMED = 6


def _leading(v: np.ndarray, names, share: float = 0.5) -> list[str]:
    """The names whose components of ``v`` carry at least ``share`` of the largest one."""
    a = np.abs(v)
    return [names[j] for j in np.flatnonzero(a >= share * a.max())] if a.size and a.max() > 0 else []


def map_ml_agreement(M: np.ndarray, r: np.ndarray, x: np.ndarray, P: np.ndarray, lower: np.ndarray,
                     upper: np.ndarray, names, fit_scale: float = 1.0) -> MapAgreement:
    """Check a MAP estimate against the data alone (the module's docstring says why).

    Parameters
    ----------
    M : ndarray, shape (n_rows, n)
        Whitened sensitivities of the scaled parameters at the MAP, rows of the converged points
        [1/scale unit].
    r : ndarray, shape (n_rows,)
        Whitened residuals (measured − model)/σ at the MAP, same rows [-].
    x : ndarray, shape (n,)
        The MAP estimate, scaled: p̃ = (p̂ − p₀)/scale [scale units].
    P : ndarray, shape (n, n)
        The MAP's prior covariance of p̃ (flat priors as a large variance) [scale units²].
    lower, upper : ndarray, shape (n,)
        Bounds of p̃ [scale units].
    names : sequence of str
        Parameter names.
    fit_scale : float
        The factor on the noise variance the estimate's covariance carries (1: the stated noise).

    Returns
    -------
    MapAgreement
    """
    noise_factor = np.sqrt(float(fit_scale))
    M, r, x = np.asarray(M, float) / noise_factor, np.asarray(r, float) / noise_factor, np.asarray(x, float)
    names = list(names)
    held = (x <= lower + AT_BOUND) | (x >= upper - AT_BOUND)
    free = np.flatnonzero(~held)
    if not free.size or not M.size:
        return MapAgreement(0, 0.0)
    b = np.flatnonzero(held)
    Pc = P[np.ix_(free, free)]
    if b.size:   # the prior of the free parameters given the held ones
        Pc = Pc - P[np.ix_(free, b)] @ np.linalg.pinv(P[np.ix_(b, b)]) @ P[np.ix_(b, free)]
    Mf = M[:, free]
    free_names = [names[j] for j in free]
    # 1. rank: the prior's null space (σ ≈ 0 along it), and the directions of it the data see
    lam, Q = np.linalg.eigh(0.5 * (Pc + Pc.T))
    sd = np.sqrt(np.clip(lam, 0.0, None))
    null = Q[:, sd < FIXED_SD * max(1.0, sd.max())]
    sM = np.linalg.svd(Mf, compute_uv=False)
    rank_tol = RANK_RTOL * (sM.max() if sM.size else 0.0)
    n_data = int(np.sum(sM > rank_tol))
    n_fixed, fixed_names = 0, []
    if null.shape[1] and rank_tol > 0:
        _, sN, VtN = np.linalg.svd(Mf @ null, full_matrices=False)
        seen = sN > rank_tol
        n_fixed = int(seen.sum())
        fixed_names = sorted({n for k in np.flatnonzero(seen) for n in _leading(null @ VtN[k], free_names)},
                             key=free_names.index)
    # 2. agreement along the data-dominated directions of the prior-whitened SVD
    L = psd_sqrt(Pc)
    U, s, Wt = np.linalg.svd(Mf @ L, full_matrices=False)
    dominant = s >= DOMINANT_S
    z = np.abs(U[:, dominant].T @ r)
    disagree = []
    if z.size and z.max() > AGREEMENT_Z:
        # the ML step along the dominated directions, parameter by parameter, in that step's own σ
        LW = (L @ Wt[dominant].T) / s[dominant]
        step = LW @ (U[:, dominant].T @ r)
        z_param = np.abs(step) / np.maximum(np.sqrt(np.sum(LW ** 2, axis=1)), 1e-300)
        order = np.argsort(z_param)[::-1]
        disagree = [free_names[j] for j in order if z_param[j] > AGREEMENT_Z][:MAX_NAMED] or \
            [free_names[order[0]]]
    return MapAgreement(int(dominant.sum()), float(z.max()) if z.size else 0.0, disagree, n_fixed, fixed_names,
                        n_data)
