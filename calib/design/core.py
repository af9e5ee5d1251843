"""``calib.design.design``: choose a campaign's operating points for a :class:`calib.design.problem.DesignProblem`.

The sensitivities of every candidate come from one call of the model's Jacobian at the linearization
point, and the criteria and the selection are those of :mod:`calib.design.criteria` and
:mod:`calib.design.select`; the result compares the design with the full candidate set and a
space-filling design of the same size.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from calib.design import candidates as cand
from calib.design.bound import relaxed_logdet_bound
from calib.design.criteria import a_criterion, d_criterion, determined_directions
from calib.design.discrepancy import Discrepancy, augment, basis
from calib.design.problem import DesignProblem
from calib.design.select import Selection, precision, select
from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["DesignResult", "design", "CRITERIA", "DEFAULT_DISCREPANCY"]

CRITERIA = ("d", "a", "prediction")

#: The default discrepancy: as large as the noise, correlated over a quarter of the envelope.
DEFAULT_DISCREPANCY = Discrepancy(1.0, 0.25)


@dataclass
class DesignResult:
    """A campaign design and how it compares (see :func:`design`).

    Attributes
    ----------
    candidates : OperatingConditions
        The candidate set (failed candidates included, ``ok`` False).
    ok : ndarray of bool
    design : ndarray of int
        Candidate index of each point of the design, fixed first (a repeat appears twice).
    fixed : ndarray of int
    selection : Selection
    sigma_prior, sigma_design, sigma_full, sigma_uniform : ndarray, shape (n,)
        Posterior 1-σ of every parameter [parameter units].
    s_design, s_full, s_uniform : ndarray
        Singular values of the prior-whitened sensitivities (s > 1: determined by the data).
    logdet : dict
        log det of the whitened precision: design, full, uniform, greedy (before exchange), and ``bound``,
        the most any design of the budget's distinct points can reach (:mod:`calib.design.bound`; without
        fixed points or repeats) [-].
    uniform : ndarray of int
        The space-filling design of the same size.
    criterion : str
    seconds : dict
        CPU seconds (time.process_time) of the sensitivities and of the selection [s].
    logdet_curve : ndarray
        log det of the parameters' whitened precision after each greedy point (the information curve,
        whatever the criterion; ``selection.greedy_order`` names the points) [-].
    """

    problem: DesignProblem
    candidates: OperatingConditions
    ok: np.ndarray
    design: np.ndarray
    fixed: np.ndarray
    selection: Selection
    sigma_prior: np.ndarray
    sigma_design: np.ndarray
    sigma_full: np.ndarray
    sigma_uniform: np.ndarray
    s_design: np.ndarray
    s_full: np.ndarray
    s_uniform: np.ndarray
    logdet: dict
    uniform: np.ndarray
    criterion: str
    seconds: dict
    H: np.ndarray = field(repr=False, default=None)
    robustness: dict = field(default_factory=dict)
    cover: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    logdet_curve: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def n_determined(self) -> dict:
        """Directions with s > 1: design, full candidate set, uniform design."""
        return {k: int(np.sum(getattr(self, f"s_{k}") > 1.0)) for k in ("design", "full", "uniform")}

    @property
    def n_failed(self) -> int:
        """Candidates the model failed at (left out)."""
        return int(np.count_nonzero(~self.ok))

    def run_order(self) -> list:
        """The design's distinct points in run order: by yaw, rotor speed and pitch line, then λ rising
        (one pitch setting at a time, the tunnel or wind speed stepped along it); candidate indices."""
        c = self.candidates
        idx = np.unique(self.design)
        lam = c.tip_speed_ratio(self.problem.envelope.radius)[idx]
        keys = np.lexsort((lam, np.round(c.pitch[idx], 6), np.round(c.rotor_speed[idx], 6), np.round(c.yaw[idx], 6)))
        return idx[keys].tolist()

    def gain_fraction(self) -> float:
        """The design's share of the full candidate set's information gain, log det A(ξ)/log det A(full) [-]."""
        return float(self.logdet["design"] / self.logdet["full"]) if self.logdet["full"] > 0 else float("nan")


def _sigma(problem: DesignProblem, A: np.ndarray) -> np.ndarray:
    """Posterior 1-σ of every parameter from the whitened precision A [parameter units]."""
    LA = problem.L @ np.linalg.inv(A)
    return np.sqrt(np.clip(np.einsum("ij,ij->i", LA, problem.L), 0.0, None)) * problem.scale


def _criterion(kind, problem, parameters, targets, disc=None):
    """The criterion on the whitened parameters, or on the parameters and the discrepancy's coefficients
    (zero weight on the coefficients for A; the true response, model plus discrepancy, for prediction)."""
    extra = 0 if disc is None else disc[1]
    if kind == "d":
        return d_criterion()
    if kind == "a":
        if not parameters:
            raise InputError("criterion 'a' needs the parameters to tighten (--parameters NAME,...)", "--criterion",
                             field="parameters")
        bad = [q for q in parameters if q not in problem.names]
        if bad:
            import difflib
            close = difflib.get_close_matches(bad[0], problem.names, 1)
            raise InputError(f"no parameter {bad[0]!r} in this model" + (f"; did you mean {close[0]!r}?" if close
                             else f"; parameters: {', '.join(problem.names)}"), "--parameters", field=bad[0])
        idx = [problem.names.index(q) for q in parameters]
        # posterior variance over prior variance of each named parameter: C = Lᵀ e_j / σ_prior,j
        Lt = problem.L.T[:, idx]
        C = np.vstack([Lt / np.linalg.norm(Lt, axis=0), np.zeros((extra, len(idx)))])
        return a_criterion(C, f"A-optimality on {', '.join(parameters)}")
    if kind == "prediction":
        Ht, ok = problem.blocks(targets)
        if disc is not None:
            Ht = augment(Ht, basis(targets, problem.envelope, disc[0]), disc[0])
        T = Ht[ok].reshape(-1, Ht.shape[-1]).T             # (n, n_targets·m): prediction variance over noise variance
        return a_criterion(T, f"prediction variance at {int(ok.sum())} target points")
    raise InputError(f"unknown criterion {kind!r}; expected one of {', '.join(CRITERIA)}", "--criterion",
                     field="criterion")


def design(problem: DesignProblem, budget: int, candidates: OperatingConditions | None = None,
           fixed: OperatingConditions | None = None, criterion: str = "d", parameters=None,
           targets: OperatingConditions | None = None, max_repeats: int = 1, n_tsr: int = 25, n_pitch: int = 16,
           n_rotor_speed: int = 1, curve_to: int | None = None, draws: int = 0, seed: int = 0,
           cover: int = 0, discrepancy: Discrepancy | None = DEFAULT_DISCREPANCY) -> DesignResult:
    """Choose ``budget`` operating points for a campaign.

    Parameters
    ----------
    problem : DesignProblem
        From :func:`problem_from_workflow`.
    budget : int
        Points in the design (fixed ones and repeats included), ≥ 1.
    candidates : OperatingConditions, optional
        The candidate set; default a λ × pitch (× rotor speed) grid over the envelope
        (:func:`calib.design.candidates.generate` with ``n_tsr``, ``n_pitch``, ``n_rotor_speed``).
        Refused when a point lies outside the envelope.
    fixed : OperatingConditions, optional
        Points the design must keep; each must be a candidate.
    criterion : {"d", "a", "prediction"}
        Bayesian D-optimality (default), A-optimality on ``parameters`` (their posterior variance
        relative to the prior's, summed), or the prediction variance of the channels at ``targets``
        (default: the candidates) relative to the noise.
    max_repeats : int
        How often one candidate may be chosen.
    curve_to : int, optional
        Greedy points for the marginal-gain curve (default min(2·budget, candidates)).
    cover : int
        Start from this many space-filling points (kept like fixed ones), the rest chosen by the
        criterion: a skeleton over the envelope against model-form error, which variance-optimal
        designs do not see (Box & Draper 1959).
    draws : int
        With draws > 0, the pseudo-Bayesian design: the criterion averaged over the linearization point
        and ``draws`` prior draws of the correction field (seeded by ``seed``), each with its own
        sensitivities; ``robustness`` then says how the locally optimal design at each draw differs.
    discrepancy : Discrepancy or None
        A smooth model discrepancy over the operating plane (:mod:`calib.design.discrepancy`; default
        as large as the noise, correlated over a quarter of the envelope): the criterion acts on the
        parameters and the discrepancy's coefficients together, so that neighbouring points stop
        counting as independent and the design spreads over the envelope. None: the model's form trusted. The reported σ, log det and directions stay
        those of the parameters under the model's own form.

    Returns
    -------
    DesignResult
    """
    env = problem.envelope
    if candidates is None:
        candidates = cand.generate(env, n_tsr, n_pitch, n_rotor_speed)
    else:
        cand.check_inside(candidates, env)
    if not isinstance(budget, (int, np.integer)) or budget <= 0:
        raise InputError(f"the budget must be a whole number of points > 0, got {budget!r}", "--budget", field="budget")
    if not isinstance(max_repeats, (int, np.integer)) or max_repeats < 1:
        raise InputError(f"repeats must be a whole number >= 1, got {max_repeats!r}", "--repeats", field="repeats")
    t0 = time.process_time()
    H, ok = problem.blocks(candidates)
    H_draws = _draw_blocks(problem, candidates, draws, seed)
    for Hk, okk in H_draws:
        ok = ok & okk
    t_sens = time.process_time() - t0
    usable = int(ok.sum())
    if budget > usable * max_repeats:
        raise InputError(f"the budget {budget} is larger than the candidate set ({usable} usable candidate(s)"
                         + (f" × {max_repeats} repeats" if max_repeats > 1 else "")
                         + (f"; {len(ok) - usable} failed" if usable < len(ok) else "") + ")", "--budget",
                         field="budget")
    fixed_idx, cover_idx = _fixed_indices(fixed, candidates, ok, env, budget, cover)
    H_crit, H_draws, crit, disc = _with_discrepancy(problem, candidates, H, H_draws, ok, discrepancy, criterion,
                                                    parameters, targets)
    t1 = time.process_time()
    usable_idx = np.flatnonzero(ok)
    Hu = H_crit[usable_idx]
    where = {int(j): k for k, j in enumerate(usable_idx)}
    curve = curve_to if curve_to is not None else min(2 * budget, usable * max_repeats)
    fixed_u = [where[int(i)] for i in fixed_idx]
    H_sel = np.stack([Hu] + [Hk[usable_idx] for Hk, _ in H_draws]) if H_draws else Hu
    sel = select(crit, H_sel, budget, fixed_u, max_repeats, curve_to=curve)
    robust = _robustness(crit, H_sel, sel.design, budget, fixed_u, max_repeats) if H_draws else {}
    t_sel = time.process_time() - t1
    sel.design = usable_idx[sel.design]
    sel.greedy_order = usable_idx[sel.greedy_order]
    chosen = sel.design
    uniform = usable_idx[cand.space_filling(candidates.subset(usable_idx), env.radius, budget)]
    A_d, A_f, A_u = precision(H, chosen), precision(H, usable_idx), precision(H, uniform)
    logdet = {k: float(np.linalg.slogdet(A)[1]) for k, A in (("design", A_d), ("full", A_f), ("uniform", A_u))}
    logdet["greedy"] = float(np.linalg.slogdet(precision(Hu, np.array([where[int(i)] for i in fixed_idx], int)))[1]
                             + np.sum(sel.greedy_gains[:budget - fixed_idx.size])) \
        if crit.kind == "d" and not H_draws and disc is None else float("nan")
    n = H.shape[-1]
    curve = _logdet_curve(H, fixed_idx, sel.greedy_order)
    if fixed_idx.size == 0 and max_repeats == 1:
        logdet["bound"] = relaxed_logdet_bound(H[usable_idx], budget, start=[where[int(i)] for i in chosen],
                                               iterations=100)["bound"]
    F = {k: A - np.eye(n) for k, A in (("design", A_d), ("full", A_f), ("uniform", A_u))}
    return DesignResult(problem, candidates, ok, chosen, fixed_idx, sel, _sigma(problem, np.eye(n)),
                        _sigma(problem, A_d), _sigma(problem, A_f), _sigma(problem, A_u),
                        determined_directions(F["design"]), determined_directions(F["full"]),
                        determined_directions(F["uniform"]), logdet, uniform, crit.name,
                        {"sensitivities": t_sens, "selection": t_sel}, H, robust, cover_idx, curve)


def _with_discrepancy(problem, candidates, H, H_draws, ok, discrepancy, criterion, parameters, targets):
    """The blocks the criterion acts on (with the discrepancy's columns when given), the draws' blocks, the
    criterion, and (discrepancy, its number of coefficients) or None."""
    if discrepancy is not None:
        phi = basis(candidates, problem.envelope, discrepancy)
        H_crit = augment(H, phi, discrepancy)
        H_draws = [(augment(Hk, phi, discrepancy), okk) for Hk, okk in H_draws]
        disc = (discrepancy, H_crit.shape[-1] - H.shape[-1])
    else:
        H_crit, disc = H, None
    crit = _criterion(criterion, problem, parameters, targets if targets is not None else candidates.subset(
        np.flatnonzero(ok)), disc)
    if disc is not None:
        crit = dataclasses.replace(crit, name=f"{crit.name} with a model discrepancy (κ {discrepancy.scale:g}, "
                                              f"ℓ {discrepancy.length:g})")
    return H_crit, H_draws, crit, disc


def _logdet_curve(H, fixed_idx, order) -> np.ndarray:
    """log det of the parameters' whitened precision (the model's form) after the fixed points and each
    greedy point in turn, shape (len(order),) [-]."""
    A = precision(H, fixed_idx)
    out = np.empty(len(order))
    for k, j in enumerate(order):
        A = A + H[j].T @ H[j]
        out[k] = np.linalg.slogdet(A)[1]
    return out


def _fixed_indices(fixed, candidates, ok, env, budget, cover):
    """The candidate indices of the fixed points and of the ``cover`` space-filling points added to them
    (checked: candidates the model converges at, within the budget)."""
    fixed_idx = np.zeros(0, int) if fixed is None or len(fixed) == 0 else \
        cand.match_points(fixed, candidates, env.radius)
    if fixed_idx.size and not np.all(ok[fixed_idx]):
        k = int(np.flatnonzero(~ok[fixed_idx])[0])
        raise InputError(f"fixed point {k + 1}: the model fails there, so it informs nothing", "fixed points",
                         line=k + 1)
    if not isinstance(cover, (int, np.integer)) or cover < 0:
        raise InputError(f"cover must be a whole number of points >= 0, got {cover!r}", "--cover", field="cover")
    cover_idx = np.zeros(0, int)
    if cover:
        mask = ok.copy()
        mask[fixed_idx] = False
        cover_idx = cand.space_filling(candidates, env.radius, int(cover), mask)
    if fixed_idx.size + cover_idx.size > budget:
        raise InputError(f"{fixed_idx.size} fixed and {cover_idx.size} cover points exceed the budget {budget}",
                         "--budget", field="budget")
    return np.concatenate([fixed_idx, cover_idx]).astype(int), cover_idx


def _draw_blocks(problem: DesignProblem, candidates, draws: int, seed: int) -> list:
    """(H, ok) of the candidates at ``draws`` prior draws of the correction field."""
    if not isinstance(draws, (int, np.integer)) or draws < 0:
        raise InputError(f"draws must be a whole number >= 0, got {draws!r}", "--draws", field="draws")
    return [problem.blocks(candidates, p) for p in problem.field_draws(draws, seed)] if draws else []


def _robustness(crit, H_sel, chosen, budget, fixed, max_repeats) -> dict:
    """How the choice changes across the prior draws: the locally optimal design at each draw (its own
    sensitivities only) against the averaged one: shared points, and each draw's criterion at the
    averaged design and at the nominal-only design, relative to its own optimum [-]."""
    from calib.design.select import select as run

    local = [run(crit, Hk, budget, fixed, max_repeats).design for Hk in H_sel]
    value = [lambda d, Hk=Hk: crit.value(precision(Hk, d)) for Hk in H_sel]
    shared = [len(set(d.tolist()) & set(chosen.tolist())) / len(set(chosen.tolist())) for d in local[1:]]
    avg_loss = [value[k](chosen) - value[k](local[k]) for k in range(1, len(H_sel))]
    nominal_loss = [value[k](local[0]) - value[k](local[k]) for k in range(1, len(H_sel))]
    return {"draws": len(H_sel) - 1, "shared_points_mean": float(np.mean(shared)),
            "shared_points_min": float(np.min(shared)),
            "averaged_design_loss_mean": float(np.mean(avg_loss)), "averaged_design_loss_worst": float(np.min(avg_loss)),
            "nominal_design_loss_mean": float(np.mean(nominal_loss)),
            "nominal_design_loss_worst": float(np.min(nominal_loss))}
