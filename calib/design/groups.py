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

Two more scores, for when the model's form is in doubt (the Phase VI tap stations,
``benchmarks/bench_design_phase_vi.py``):

- **Held-out squared error of the calibration as run** (:func:`subset_heldout_error`): the
  calibration ignores the discrepancy, the truth carries it; the expected squared held-out error of
  the target channels is the Bayesian variance tr(C_f A_{−f}⁻¹ C_fᵀ) plus the bias the discrepancy
  at the training data and at the target puts into the prediction, ‖C_f A_{−f}⁻¹ H_{−f}ᵀ D_{−f} − D_f‖²_F
  (the integrated mean squared error of Box & Draper 1959 with a random discrepancy); smaller is better.
- **Sequential** (:func:`subset_sequential`): with a calibrated campaign's posterior as the prior
  (``--after``), the posterior variance of the target channels' model output at the points after the
  optional groups' data alone (their discrepancy carried as coefficients); smaller is better.

References
----------
G.E.P. Box, N.R. Draper, A basis for the selection of a response surface design, J. Am. Stat. Assoc.
54 (1959) 622-654.
K. Chaloner, I. Verdinelli, Bayesian experimental design: a review, Statistical Science 10 (1995)
273-304.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np

from calib.design.discrepancy import Discrepancy, augment, basis
from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["subset_scores", "subset_heldout_error", "subset_sequential"]


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
    H, optional, base, t_rows, n = _prepared(problem, conditions, k, always, targets)
    if discrepancy is not None:
        H = augment(H, basis(conditions, problem.envelope, discrepancy), discrepancy)
    folds = _folds(conditions, leave_out)
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


def _folds(conditions, leave_out) -> list:
    groups = (np.arange(len(conditions)) if leave_out == "point"
              else np.round(np.asarray(getattr(conditions, leave_out), float), 6))
    return [groups == v for v in np.unique(groups)]


def _prepared(problem, conditions, k, always, targets):
    """Check the choice; the whitened blocks, the optional groups, the always-measured channels, the
    targets' rows and the number of parameters."""
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
    base = [c for g in problem.groups if g.name in set(always) for c in g.channels]
    return H, optional, base, _rows(problem, targets), H.shape[-1]


def subset_heldout_error(problem, conditions: OperatingConditions, k: int, always=(), targets=(),
                         discrepancy: Discrepancy | None = None, leave_out: str = "wind_speed") -> list[dict]:
    """Score every choice of ``k`` optional sensor groups by the expected held-out squared error of the
    target channels when the calibration ignores the model discrepancy the truth carries.

    With the whitened blocks H (parameters w ~ N(0, I), unit noise) and the discrepancy's columns D
    (coefficients b ~ N(0, I), :func:`calib.design.discrepancy.augment`), the calibration without the
    discrepancy estimates ŵ = A⁻¹ Hᵀ y from the training folds, A = I + HᵀH, and predicts C ŵ at the fold
    left out, whose true response is C w + D_f b. The expected squared error is
    tr(C A⁻¹ Cᵀ) + ‖C A⁻¹ Hᵀ D − D_f‖²_F (Box & Draper 1959: variance plus squared bias, the bias here
    random), per held-out point, averaged over the folds.

    Parameters
    ----------
    As :func:`subset_scores`; without ``discrepancy`` the score is the plain held-out variance.

    Returns
    -------
    list of dict
        One per subset: ``groups``, ``channels``, ``heldout_error`` [target noise variances], its parts
        ``variance`` and ``bias``, in the order of :func:`itertools.combinations`.
    """
    H, optional, base, t_rows, n = _prepared(problem, conditions, k, always, targets)
    D = (augment(H, basis(conditions, problem.envelope, discrepancy), discrepancy)[..., n:]
         if discrepancy is not None else np.zeros(H.shape[:2] + (0,)))
    folds = _folds(conditions, leave_out)
    out = []
    for subset in combinations(optional, k):
        chans = list(dict.fromkeys(base + [c for g in subset for c in g.channels]))
        rows = _rows(problem, chans)
        var, bias = [], []
        for f in folds:
            Hs = H[~f][:, rows, :].reshape(-1, n)
            Ds = D[~f][:, rows, :].reshape(Hs.shape[0], -1)
            C = H[f][:, t_rows, :].reshape(-1, n)
            Df = D[f][:, t_rows, :].reshape(C.shape[0], -1)
            A = np.eye(n) + Hs.T @ Hs
            G = np.linalg.solve(A, C.T)                                 # A⁻¹ Cᵀ
            m_f = max(int(f.sum()), 1)
            var.append(float(np.sum(C.T * G)) / m_f)
            bias.append(float(np.sum((G.T @ (Hs.T @ Ds) - Df) ** 2)) / m_f)
        v, b = float(np.mean(var)), float(np.mean(bias))
        out.append({"groups": [g.name for g in subset], "channels": chans, "heldout_error": v + b,
                    "variance": v, "bias": b})
    return out


def subset_sequential(problem, conditions: OperatingConditions, k: int, always=(), targets=(),
                      discrepancy: Discrepancy | None = None) -> list[dict]:
    """Score every choice of ``k`` optional sensor groups added to a calibrated campaign.

    ``problem`` carries the campaign's posterior as its prior (``problem_from_workflow(after=...)``), so the
    ``always`` groups' data are already in it: the optional groups' data alone update it. The score is the
    posterior variance of the target channels' model output at the points, tr(C A⁻¹ Cᵀ) per point, where A
    is the precision of the parameters and of the optional groups' discrepancy coefficients (their prior
    N(0, I)), C the targets' rows with zero discrepancy columns: how much of what the campaign left
    uncertain in the targets the groups determine, through the parameters.

    Returns
    -------
    list of dict
        One per subset: ``groups``, ``channels`` (the optional ones) and ``target_variance`` [target noise
        variances], in the order of :func:`itertools.combinations`.
    """
    H, optional, base, t_rows, n = _prepared(problem, conditions, k, always, targets)
    if discrepancy is not None:
        H = augment(H, basis(conditions, problem.envelope, discrepancy), discrepancy)
    C = H[:, t_rows, :n].reshape(-1, n)
    out = []
    for subset in combinations(optional, k):
        chans = [c for g in subset for c in g.channels if c not in base]
        B = H[:, _rows(problem, chans), :].reshape(-1, H.shape[-1])
        A = np.eye(H.shape[-1]) + B.T @ B
        Cp = np.zeros((len(C), H.shape[-1]))
        Cp[:, :n] = C
        var = float(np.sum(Cp.T * np.linalg.solve(A, Cp.T))) / len(conditions)
        out.append({"groups": [g.name for g in subset], "channels": chans, "target_variance": var})
    return out
