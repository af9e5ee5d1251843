r"""Which k of several optional sensor groups to add to the ones always measured, at given operating
points: every subset scored by the information on the parameters and by the held-out prediction
variance of target channels.

For a subset S of the optional groups (plus the ``always`` ones), with the prior-whitened blocks
H_j of the points (:meth:`calib.design.problem.DesignProblem.blocks`) restricted to the channels of
S, optionally with the model discrepancy's columns (:mod:`calib.design.discrepancy`):

- **D**: log det of the parameters' posterior precision with the discrepancy's coefficients
  integrated out, log det A − log det A_bb (the Schur complement of the augmented precision; the
  Bayesian D_s-criterion, Chaloner & Verdinelli 1995, § 2.2); larger is better.
- **Held-out prediction variance**: the calibration's own check, one point (one group of equal
  ``leave_out`` values) left out at a time: the posterior predictive variance of the target
  channels' true response (model plus discrepancy) at the held-out point from the data at the
  others, tr(C_fᵀ A_{−f}⁻¹ C_f) with C_f the targets' (augmented) rows there, in units of their noise
  variance, averaged over the folds; smaller is better.

References
----------
K. Chaloner, I. Verdinelli, Bayesian experimental design: a review, Statistical Science 10 (1995)
273-304.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from calib.design.discrepancy import Discrepancy, augment, basis
from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["subset_scores"]


def _rows(problem, names) -> list[int]:
    return [problem.channels.index(c) for c in names]


def subset_scores(problem, conditions: OperatingConditions, k: int, always=(), targets=(),
                  discrepancy: Discrepancy | None = None, leave_out: str = "wind_speed") -> list[dict]:
    """Score every choice of ``k`` optional sensor groups.

    Parameters
    ----------
    problem : DesignProblem
        Built with every group (``sensors``); its groups not named in ``always`` are the optional ones.
    conditions : OperatingConditions
        The operating points measured.
    k : int
        Optional groups chosen, 0 ≤ k ≤ their number.
    always : sequence of str
        Groups always measured (names as in ``--sensors``).
    targets : sequence of str
        Channels whose held-out prediction is scored (each must be in the problem).
    discrepancy : Discrepancy, optional
    leave_out : str
        Condition whose equal values form a fold (``wind_speed``, ``rotor_speed``, ``pitch``), or ``point``.

    Returns
    -------
    list of dict
        One per subset: ``groups`` (names), ``channels``, ``logdet`` (D_s) and ``heldout_variance``
        [target noise variances], in the order of :func:`itertools.combinations`.
    """
    names = [g.name for g in problem.groups]
    bad = [g for g in always if g not in names]
    if bad:
        raise InputError(f"group {bad[0]!r} is not among the design's sensor groups ({', '.join(names)})",
                         "--sensors", field=bad[0])
    optional = [g for g in problem.groups if g.name not in set(always)]
    if not isinstance(k, (int, np.integer)) or not 0 <= k <= len(optional):
        raise InputError(f"k must be 0..{len(optional)} (the optional groups), got {k!r}", "k", field="k")
    missing = [c for c in targets if c not in problem.channels]
    if missing:
        raise InputError(f"target channel {missing[0]!r} is not produced by the chosen groups "
                         f"({', '.join(problem.channels)})", "targets", field=missing[0])
    H, ok = problem.blocks(conditions)
    if not np.all(ok):
        raise InputError(f"the model fails at {int(np.sum(~ok))} of the {len(ok)} points", "conditions",
                         field="conditions")
    n = H.shape[-1]
    if discrepancy is not None:
        H = augment(H, basis(conditions, problem.envelope, discrepancy), discrepancy)
    base = [c for g in problem.groups if g.name in set(always) for c in g.channels]
    groups = (np.arange(len(conditions)) if leave_out == "point"
              else np.round(np.asarray(getattr(conditions, leave_out), float), 6))
    folds = [groups == v for v in np.unique(groups)]
    t_rows = _rows(problem, targets)
    out = []
    for subset in combinations(optional, k):
        chans = list(dict.fromkeys(base + [c for g in subset for c in g.channels]))
        rows = _rows(problem, chans)
        B = H[:, rows, :]                                             # (n_points, m_S, n_aug)
        per_point = np.einsum("jmi,jmk->jik", B, B)
        A = np.eye(H.shape[-1]) + per_point.sum(axis=0)
        logdet = float(np.linalg.slogdet(A)[1] - (np.linalg.slogdet(A[n:, n:])[1] if A.shape[0] > n else 0.0))
        var = []
        for f in folds:
            Af = A - per_point[f].sum(axis=0)
            C = H[f][:, t_rows, :].reshape(-1, H.shape[-1]).T
            var.append(float(np.sum(C * np.linalg.solve(Af, C))) / max(int(f.sum()), 1))
        out.append({"groups": [g.name for g in subset], "channels": chans, "logdet": logdet,
                    "heldout_variance": float(np.mean(var)) if targets else float("nan")})
    return out
