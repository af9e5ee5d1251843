"""Greedy forward selection and a Fedorov exchange pass over candidate blocks (:mod:`calib.design.criteria`).

Greedy: from the fixed points, add the candidate with the largest gain of the criterion, one at a
time (Wynn-type forward selection, Wynn 1970), updating A⁻¹ by Woodbury. Exchange: for every
point that is not fixed, remove it (a Woodbury downdate) and put back the best candidate when that
raises the criterion (Fedorov 1972, the exchange algorithm), pass after pass until a pass changes
nothing. The gains of all candidates are one batched product per step.

References
----------
H.P. Wynn, The sequential generation of D-optimum experimental designs, Ann. Math. Stat. 41
(1970) 1655-1664.
V.V. Fedorov, Theory of Optimal Experiments, Academic Press (1972), ch. 3.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.design.criteria import Criterion, woodbury

__all__ = ["Selection", "precision", "select"]

#: An exchange is taken when it raises the criterion by more than this (relative, at least absolute).
EXCHANGE_TOLERANCE = 1e-9


@dataclass
class Selection:
    """A chosen design.

    Attributes
    ----------
    design : ndarray of int
        Candidate indices of the design, the fixed ones first, then in the order greedy added them
        (an exchanged point takes the place of the one it replaced); a candidate appears once per repeat.
    value : float
        The criterion at the design [-].
    greedy_gains : ndarray
        The criterion's gain of each greedy step after the fixed points, for as many steps as
        asked (the marginal-gain curve; may run past the budget) [-].
    greedy_value : float
        The criterion after the greedy part at the budget, before exchange [-].
    greedy_order : ndarray of int
        The candidate added at each greedy step (as many as ``greedy_gains``).
    exchanges : int
        Points the exchange replaced.
    passes : int
        Exchange passes run.
    """

    design: np.ndarray
    value: float
    greedy_gains: np.ndarray
    greedy_value: float
    greedy_order: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    exchanges: int = 0
    passes: int = 0
    notes: list = field(default_factory=list)


def precision(H: np.ndarray, design, A0: np.ndarray | None = None) -> np.ndarray:
    """The whitened posterior precision A = A0 + Σ_{j∈design} H_jᵀH_j (A0 = I by default); with
    H of shape (..., n_c, m, n), one per leading (prior-draw) index."""
    n = H.shape[-1]
    A = np.eye(n) if A0 is None else np.array(A0, float)
    d = np.asarray(design, int)
    if d.size:
        B = H[..., d, :, :].reshape(*H.shape[:-3], -1, n)
        A = A + np.swapaxes(B, -1, -2) @ B
    return A * np.ones(H.shape[:-3] + (1, 1))


def select(criterion: Criterion, H: np.ndarray, budget: int, fixed=(), max_repeats: int = 1,
           curve_to: int | None = None, exchange: bool = True, max_passes: int = 10) -> Selection:
    """Choose ``budget`` points (fixed ones included) maximizing ``criterion``.

    Parameters
    ----------
    criterion : Criterion
    H : ndarray, shape (n_candidates, m, n) or (n_draws, n_candidates, m, n)
        The candidates' prior-whitened blocks (:mod:`calib.design.criteria`); with a leading axis,
        at several parameter vectors (prior draws), the criterion averaged over them.
    budget : int
        Points in the design, the fixed ones included (repeats count).
    fixed : sequence of int
        Candidates that must be in the design (kept by the exchange).
    max_repeats : int
        How often one candidate may be chosen (1: distinct points).
    curve_to : int, optional
        Run the greedy part to this many points for the marginal-gain curve (≥ budget).
    exchange : bool
        Run the exchange after greedy.
    max_passes : int
        Exchange passes at most.

    Returns
    -------
    Selection
    """
    n_c = H.shape[-3]
    fixed = [int(i) for i in fixed]
    counts = np.bincount(np.asarray(fixed, int), minlength=n_c) if fixed else np.zeros(n_c, int)
    steps = min(max(budget, curve_to or 0), n_c * max_repeats) - len(fixed)
    design, counts, Ainv, value, gains, order = _greedy(criterion, H, budget, fixed, counts, max_repeats, steps)
    out = Selection(np.array(design, int), value, np.array(gains), value, np.array(order, int))
    if exchange:
        _exchange(criterion, H, out, design, counts, Ainv, len(fixed), max_repeats, max_passes)
    return out


def _greedy(criterion, H, budget, fixed, counts, max_repeats, steps):
    """Forward selection from ``fixed``: the design, counts and A⁻¹ at ``budget`` points, the
    criterion there, and the gains and candidates of all ``steps`` points added."""
    A = precision(H, fixed)
    Ainv = np.linalg.inv(A)
    value = criterion.value(A, Ainv)
    design, gains, order = list(fixed), [], []
    kept = (list(design), counts.copy(), Ainv.copy(), value)
    for _ in range(max(steps, 0)):
        g = criterion.gains(Ainv, H)
        g[counts >= max_repeats] = -np.inf
        c = int(np.argmax(g))
        if not np.isfinite(g[c]):
            break
        design.append(c)
        counts[c] += 1
        Ainv = woodbury(Ainv, H[..., c, :, :])
        value += float(g[c])
        gains.append(float(g[c]))
        order.append(c)
        if len(design) == budget:
            kept = (list(design), counts.copy(), Ainv.copy(), value)
    return (*kept, gains, order)


def _exchange(criterion, H, out, design, counts, Ainv, n_fixed, max_repeats, max_passes):
    """Fedorov exchange on ``design`` in place; ``out`` gets the design, value, exchanges and passes."""
    value = out.value
    for k in range(max_passes):
        changed = 0
        for pos in range(n_fixed, len(design)):
            i = design[pos]
            loss = criterion.removal(Ainv, H[..., i, :, :])
            A_minus = woodbury(Ainv, H[..., i, :, :], -1.0)
            g = criterion.gains(A_minus, H)
            room = counts.copy()
            room[i] -= 1
            g[room >= max_repeats] = -np.inf
            c = int(np.argmax(g))
            delta = loss + float(g[c])
            if c != i and delta > EXCHANGE_TOLERANCE * max(1.0, abs(value)):
                design[pos] = c
                counts[i] -= 1
                counts[c] += 1
                Ainv = woodbury(A_minus, H[..., c, :, :])
                value += delta
                changed += 1
        out.passes = k + 1
        out.exchanges += changed
        # refreshed from scratch once a pass: no drift of the rank-m updates
        A = precision(H, design)
        Ainv = np.linalg.inv(A)
        value = criterion.value(A, Ainv)
        if not changed:
            break
    out.design, out.value = np.array(design, int), value
