r"""The estimators: damped Gauss–Newton under bounds in a subspace of the scaled parameters,
for maximum likelihood (:func:`estimate_ml`) and maximum a posteriori (:func:`estimate_map`).

Notes
-----
In p = p₀ + D B θ (:mod:`calib.calibration.problem`) each iteration linearizes the model
(exact model Jacobian, ``ForwardModel.jacobian``) and solves the Gauss–Newton
(Levenberg–Marquardt damped) quadratic program

.. math::  \min_δ ½ δᵀ(H + μ\,\mathrm{diag}(H))δ + gᵀδ
           \quad\text{s.t.}\quad l̃ − Bθ ≤ Bδ ≤ ũ − Bθ,

with H = JᵀJ and g = Jᵀr̃ for ML, H = JᵀJ + I and g = Jᵀr̃ + θ for the MAP (its prior term
½‖θ‖² is exact in its Gauss–Newton model), where l̃, ũ are the parameter bounds (including
C_D ≥ C_D,min at the grid points) in scaled units. The named optimizer of
:mod:`calib.calibration.qp` solves that subproblem. The steps of one iteration:

1. :func:`_normal_equations`: H, g and the damping's diagonal at the current θ;
2. :func:`_damped_step`: the QP with growing damping until a step lowers the cost without
   failing more model points (accepted, μ updated by the gain ratio ρ, Nielsen's rule) or the
   tries run out;
3. :func:`_take`: the accepted step becomes the state, recorded;
4. :class:`StopRule`: stop on a small cost decrease or a small step.

The MAP adds to H the residuals' curvature S ≈ Σ r_i ∇²r_i that JᵀJ leaves out (:mod:`calib.calibration.secant`)
once a Gauss–Newton step has overshot, while its steps are predicted well; a secant step that needed
more damping, or the subproblem with S failing, hands over to Gauss–Newton's model.

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
J. Nocedal, S.J. Wright, Numerical Optimization, 2nd ed., Springer (2006), ch. 10, 18.
H.B. Nielsen, Damping parameter in Marquardt's method, IMM-REP-1999-05, DTU (1999).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from calib.calibration.estimation_parts import (DAMPING_TRIES, JACOBIAN_REUSE_STEP, MAX_SHRINK_SOLVES, MIN_DAMPING,
                                               SHRINK_AFTER_REJECTION, EstimationOutcome, EstimationStatus, StopRule,
                                               broyden_update, feasible_start, feasible_step, jacobian_reuse_step)
from calib.calibration.problem import LeastSquaresProblem, Linearization
from calib.calibration.qp import QpSolution, get_optimizer
from calib.calibration.secant import SECANT_RHO, SECANT_START, psd_part, secant_update


def estimate_ml(problem: LeastSquaresProblem, basis: np.ndarray, theta0: np.ndarray | None = None,
                optimizer: str = "sqpmethod", stop: StopRule = StopRule(),
                callback: Callable[[dict], None] | None = None, stage: str = "estimate",
                broyden: bool = False) -> EstimationOutcome:
    """Constrained maximum-likelihood estimate of θ in p = p₀ + D B θ.

    Parameters
    ----------
    problem : LeastSquaresProblem
    basis : ndarray, shape (n_params, n_theta)
        B (identity for full nodal ML, V_ID for the truncated-SVD estimator).
    theta0 : ndarray, shape (n_theta,), optional
        Start (default 0, i.e. nominal).
    optimizer : str
        Name in :data:`calib.calibration.qp.OPTIMIZERS`.
    stop : StopRule
    callback : callable(dict), optional
        Called after every iteration with keys stage, iteration, cost, step, damping, n_failed, qp.
    stage : str
        Name of the estimation in the callback's records.
    broyden : bool
        Broyden's update of the model Jacobian after an accepted step, as in :func:`estimate_map`.

    Returns
    -------
    EstimationOutcome
    """
    return _gauss_newton(problem, basis, theta0, optimizer, stop, callback, stage, prior_weight=0.0,
                         broyden=broyden)


def estimate_map(problem: LeastSquaresProblem, prior_root: np.ndarray, u0: np.ndarray | None = None,
                 optimizer: str = "sqpmethod", stop: StopRule = StopRule(),
                 callback: Callable[[dict], None] | None = None, stage: str = "map",
                 broyden: bool = False) -> EstimationOutcome:
    """Constrained maximum a posteriori estimate under the prior p̃ ~ N(0, P), P = L Lᵀ.

    In the prior-whitened coordinates u (p̃ = L u) the prior term is ½‖u‖², added to the cost
    (:class:`calib.calibration.calibrator.Calibrator`, ``estimator = "map"``).

    Parameters
    ----------
    problem : LeastSquaresProblem
    prior_root : ndarray, shape (n_params, n_u)
        L.
    u0 : ndarray, shape (n_u,), optional
        Start (default 0, i.e. nominal).
    optimizer, stop, callback, stage
        As in :func:`estimate_ml`.
    broyden : bool
        After an accepted step, update the model Jacobian by Broyden's rank-one secant update from the
        step's evaluation instead of a new model Jacobian (:func:`broyden_update`); a fresh model Jacobian
        replaces the update when a step under it is rejected and before the iteration may stop, so the
        estimate and its covariance rest on a model Jacobian (taken there, or within
        :func:`~calib.calibration.estimation_parts.jacobian_reuse_step` of it: a tenth of the model's difference
        step). For models whose Jacobian costs simulations of its own (finite differences); the residuals'
        secant curvature is then not used.

    Returns
    -------
    EstimationOutcome
        ``cost`` includes the prior term.
    """
    return _gauss_newton(problem, prior_root, u0, optimizer, stop, callback, stage, prior_weight=1.0,
                         secant=not broyden, broyden=broyden)


@dataclass
class _Iteration:
    """The state every step of the iteration reads and changes."""

    problem: LeastSquaresProblem
    basis: np.ndarray
    lb: np.ndarray                 # bounds of p̃ [scale units]
    ub: np.ndarray
    prior_weight: float            # 1 for the MAP's ½‖θ‖², 0 for ML
    theta: np.ndarray
    lin: Linearization
    mu: float = MIN_DAMPING
    curvature: np.ndarray | None = None   # the secant estimate of the residuals' curvature S (None: Gauss-Newton)
    status: EstimationStatus = EstimationStatus.MAX_ITERATIONS
    message: str = ""
    history: list = field(default_factory=list)
    noise_available: float | None = None  # set when a noisy model's iteration ended converged to its noise
    rejected: int = 0                     # trial steps evaluated and rejected, in all
    approximate: bool = False             # lin.M is a Broyden update, not the model's Jacobian
    refresh: bool = False                 # a step under the Broyden update was rejected: a model Jacobian first
    updates: int = 0                      # Broyden updates made
    anchor: np.ndarray | None = None      # p̃ where lin.M was taken from the model (None: an update)
    reuse_step: float = JACOBIAN_REUSE_STEP   # a step ending this near the anchor keeps lin.M [scale units]

    def cost(self, at: Linearization, theta: np.ndarray) -> float:
        """Half the χ² at ``at``, plus the prior term of ``theta``."""
        return at.cost + 0.5 * self.prior_weight * float(theta @ theta)

    def end(self, status: EstimationStatus, message: str) -> None:
        self.status, self.message = status, message


@dataclass
class _Trial:
    """One accepted damped step: the step, the model there and its cost, the QP's answer."""

    x: np.ndarray
    lin: Linearization
    cost: float
    qp: QpSolution
    rho: float = 1.0          # actual / predicted decrease
    first_try: bool = True    # accepted without raising the damping
    rejected: int = 0         # trial steps evaluated and rejected before it


def _gauss_newton(problem, basis, theta0, optimizer, stop: StopRule, callback, stage, prior_weight,
                  secant: bool = False, broyden: bool = False) -> EstimationOutcome:
    """The damped Gauss–Newton iteration of :func:`estimate_ml` and :func:`estimate_map` (with ``secant``
    the residuals' curvature added to its model, :mod:`calib.calibration.secant`; with ``broyden`` the
    Jacobian updated from the accepted steps, :func:`broyden_update`)."""
    qp = get_optimizer(optimizer)
    basis = np.asarray(basis, float)
    statement = problem.statement
    lb = (statement.lower - statement.p0) / statement.scale
    ub = (statement.upper - statement.p0) / statement.scale
    theta = feasible_start(basis, theta0, lb, ub)
    run = _Iteration(problem, basis, lb, ub, prior_weight, theta, problem.linearize(problem.p_of(basis, theta)),
                     message=f"stopped after {stop.max_iterations} iterations")
    if basis.shape[1] == 0:
        return EstimationOutcome(theta, run.lin.p, run.cost(run.lin, theta), 0, EstimationStatus.CONVERGED,
                                 "nothing to estimate", run.lin, run.history)
    # a damped trial is only evaluated when the model's Jacobian costs simulations of its own (finite
    # differences: 2 n more per point); with exact derivatives the Jacobian comes with the values
    linearize_trials = problem.model.capabilities.derivatives == "exact"
    if secant:
        run.curvature = np.zeros((basis.shape[1], basis.shape[1]))
    run.anchor = basis @ theta
    run.reuse_step = jacobian_reuse_step(getattr(problem.model.capabilities, "difference_step", None))
    it = 0
    for it in range(1, stop.max_iterations + 1):
        H, g, dH = _normal_equations(run)
        cost_now = run.cost(run.lin, run.theta)
        trial, x = _damped_step(run, qp, optimizer, H, g, dH, cost_now, linearize_trials, stop)
        secant_used = run.curvature is not None and bool(np.any(run.curvature))
        if trial is None or run.refresh or run.noise_available is not None:
            if _without_step(run, stop, it, x, secant_used):
                break
            continue
        before, from_model = run.lin, not run.approximate
        decrease, step = _take(run, trial, cost_now, stage, it, callback, broyden)
        if stop.small_decrease(decrease, trial.cost) or stop.small_step(step, run.theta):
            if secant_used and not trial.first_try:     # a damped secant step: Gauss-Newton's decides
                run.curvature[:] = 0.0
                continue
            if run.approximate:         # the estimate's model Jacobian; a step made under the update:
                _fresh_jacobian(run, stop)  # the model's Jacobian decides whether it was the last
                if not from_model and not _model_converged(run, qp, stop):
                    continue
            _stopped(run, trial.qp, stop, step, optimizer, it)
            break
        if run.curvature is not None:
            # an overshooting Gauss-Newton step starts it; a poorly predicted or damped secant step resets it
            if trial.first_try and (trial.rho >= SECANT_RHO if secant_used else trial.rho < SECANT_START):
                run.curvature = secant_update(run.curvature, before, run.lin, run.basis, trial.x, prior_weight)
            else:
                run.curvature[:] = 0.0
    if run.approximate:                 # out of iterations under the update: the estimate's model Jacobian
        run.lin = problem.linearize(run.lin.p)
    problem.remember(run.lin)
    return EstimationOutcome(run.theta, run.lin.p, run.cost(run.lin, run.theta), it, run.status, run.message,
                             run.lin, run.history, run.rejected, run.updates)


def _without_step(run: _Iteration, stop: StopRule, it: int, x, secant_used: bool) -> bool:
    """An iteration that took no step: whether the estimation ends. A rejection under Broyden's update, or
    no step under it, takes the model's Jacobian and goes on; a stop at the noise, a failed subproblem or
    no step under the secant curvature hand over to Gauss–Newton's model; else the status is set."""
    if run.refresh or run.approximate:          # rejected under the update, or stopping: the model's Jacobian
        _fresh_jacobian(run, stop)
        return False
    if secant_used:
        run.noise_available = None      # the secant model failed or predicted: Gauss-Newton's decides
        run.curvature[:] = 0.0
        if run.status != EstimationStatus.QP_FAILED:
            run.mu = MIN_DAMPING
        run.end(EstimationStatus.MAX_ITERATIONS, f"stopped after {stop.max_iterations} iterations")
        return False
    if run.noise_available is not None:
        _noise_stop(run, stop, it)
    elif run.status != EstimationStatus.QP_FAILED:
        _no_step(run, x, stop, it)
    return True


def _normal_equations(run: _Iteration) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H, g of the Gauss–Newton model at the current θ, and the diagonal the damping scales."""
    J = -(run.lin.M @ run.basis)
    r = run.lin.residual.reshape(-1)
    H = J.T @ J + run.prior_weight * np.eye(run.basis.shape[1])
    if run.curvature is not None:
        H = H + psd_part(run.curvature)
    g = J.T @ r + run.prior_weight * run.theta
    dH = np.maximum(np.diag(H), 1e-12 * max(np.max(np.diag(H)), 1e-300))
    return H, g, dH


def _damped_step(run: _Iteration, qp, optimizer: str, H, g, dH, cost_now: float,
                 linearize_trials: bool, stop: StopRule = StopRule()) -> tuple[_Trial | None, np.ndarray | None]:
    """The first damped step that lowers the cost without failing more points, with μ updated;
    (None, the last step tried) when the tries run out, or with ``stop.noise_decrease`` when a step
    was rejected although the least damped step predicts no more than that decrease (the status set
    converged and ``run.noise_available`` to that predicted decrease); (None, None) with the status
    set when the QP fails."""
    noisy = stop.noise_decrease > 0.0
    root_d = np.sqrt(dH)

    def solve(mu):
        sol = qp(H + mu * np.diag(dH), g, run.basis, run.lb - run.basis @ run.theta, run.ub - run.basis @ run.theta)
        if not sol.success and not np.all(np.isfinite(sol.x)):
            run.end(EstimationStatus.QP_FAILED, f"{optimizer}: {sol.message}")
            return sol, None, 0.0
        x = feasible_step(run.basis, run.theta, sol.x, run.lb, run.ub)
        return sol, x, float(-(g @ x + 0.5 * x @ H @ x))

    x = None
    rejected_length = None      # the scaled length of the last rejected step (noisy models)
    available = None            # the least damped step's predicted decrease (noisy models)
    shrink_solves = 0
    for i in range(DAMPING_TRIES):
        sol, x, predicted = solve(run.mu)
        if x is None:
            return None, None
        # after a rejection, a step of at most SHRINK_AFTER_REJECTION of its length, found by the subproblem alone
        while (rejected_length is not None and np.linalg.norm(root_d * x) > SHRINK_AFTER_REJECTION * rejected_length
               and shrink_solves < MAX_SHRINK_SOLVES):
            run.mu *= 4.0
            shrink_solves += 1
            sol, x, predicted = solve(run.mu)
            if x is None:
                return None, None
        p_trial = run.problem.p_of(run.basis, run.theta + x)
        trial = run.problem.linearize(p_trial) if linearize_trials else run.problem.evaluate(p_trial)
        cost_trial = run.cost(trial, run.theta + x)
        if trial.n_failed <= run.lin.n_failed and cost_trial <= cost_now:
            rho = (cost_now - cost_trial) / predicted if predicted > 0 else 1.0
            run.mu = max(run.mu * max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3), 1e-12)
            return _Trial(x, trial, cost_trial, sol, rho, i == 0, i), x
        run.rejected += 1
        if run.approximate:     # the update mispredicted: a model Jacobian before any further damping
            run.refresh = True
            return None, x
        if noisy:
            if available is None:
                available = predicted if run.mu <= MIN_DAMPING else solve(MIN_DAMPING)[2]
            if available <= stop.noise_decrease:
                run.noise_available = available
                run.end(EstimationStatus.CONVERGED, "converged to the model's noise")
                return None, x
            rejected_length = float(np.linalg.norm(root_d * x))
        run.mu = max(run.mu * 4.0, MIN_DAMPING)
    return None, x


def _no_step(run: _Iteration, x: np.ndarray, stop: StopRule, it: int) -> None:
    """No damped step lowered the cost: a stationary point when even the last, smallest step is
    below the tolerance, else a stall."""
    run.problem.remember(run.lin)       # the cache may hold the last rejected trial
    if float(np.linalg.norm(x)) <= stop.step_tolerance * (1.0 + np.linalg.norm(run.theta)):
        run.end(EstimationStatus.CONVERGED, f"converged in {it - 1} iterations (no smaller step decreases the cost)")
    else:
        run.end(EstimationStatus.STALLED, "no step decreased the cost (damping exhausted)")


def _fresh_jacobian(run: _Iteration, stop: StopRule) -> None:
    """The model's Jacobian at the current point in place of the Broyden update (its outputs are the
    ones evaluated there), the damping and the status reset: the iteration goes on from there."""
    run.lin = run.problem.linearize(run.lin.p)
    run.approximate = run.refresh = False
    run.anchor = run.basis @ run.theta
    run.noise_available = None
    run.mu = MIN_DAMPING
    run.end(EstimationStatus.MAX_ITERATIONS, f"stopped after {stop.max_iterations} iterations")


def _model_converged(run: _Iteration, qp, stop: StopRule) -> bool:
    """Whether the least damped step of the Gauss–Newton model at the current point (on a model
    Jacobian) is below the stop rule's decrease or step tolerance (no model call)."""
    H, g, dH = _normal_equations(run)
    sol = qp(H + MIN_DAMPING * np.diag(dH), g, run.basis, run.lb - run.basis @ run.theta, run.ub - run.basis @ run.theta)
    if not np.all(np.isfinite(sol.x)):
        return False
    x = feasible_step(run.basis, run.theta, sol.x, run.lb, run.ub)
    predicted = float(-(g @ x + 0.5 * x @ H @ x))
    cost = run.cost(run.lin, run.theta)
    return stop.small_decrease(predicted, cost) or stop.small_step(float(np.linalg.norm(x)), run.theta)


def _noise_stop(run: _Iteration, stop: StopRule, it: int) -> None:
    """A rejected step although the least damped step predicted at most ``stop.noise_decrease``:
    converged to the model's noise (the current point kept, its linearization cached)."""
    run.problem.remember(run.lin)       # the cache may hold the rejected trial
    run.end(EstimationStatus.CONVERGED,
            f"converged to the model's noise in {it - 1} iterations (the Gauss-Newton step predicted a decrease of "
            f"{run.noise_available:.2g} <= {stop.noise_decrease:g}, about {np.sqrt(2 * max(run.noise_available, 0)):.2f} "
            "standard deviations, and raised the cost)")


def _take(run: _Iteration, trial: _Trial, cost_now: float, stage: str, it: int, callback,
          broyden: bool = False) -> tuple[float, float]:
    """Move to the accepted trial (linearized there if it was only evaluated: by the model, or by
    Broyden's update with ``broyden`` where the same points converged); record the iteration; return
    the cost decrease and the step length [scale units]."""
    if trial.lin.M is None:             # the accepted trial's sensitivities
        near = run.anchor is not None and np.max(np.abs(run.basis @ (run.theta + trial.x) - run.anchor)) \
            <= run.reuse_step
        if broyden and np.array_equal(trial.lin.ok, run.lin.ok) and near:
            # within a small fraction of the difference steps of the model Jacobian: that Jacobian
            trial.lin = Linearization(trial.lin.p, trial.lin.residual, trial.lin.ok, run.lin.M, trial.lin.evaluation)
        elif broyden and np.array_equal(trial.lin.ok, run.lin.ok):
            M = broyden_update(run.lin.M, run.lin.residual.reshape(-1), trial.lin.residual.reshape(-1),
                               run.basis @ trial.x, trial.lin.ok, run.lin.residual.shape[1])
            trial.lin = Linearization(trial.lin.p, trial.lin.residual, trial.lin.ok, M, trial.lin.evaluation)
            run.approximate, run.anchor = True, None
            run.updates += 1
        else:
            trial.lin = run.problem.linearize(trial.lin.p)
            run.approximate, run.anchor = False, run.basis @ (run.theta + trial.x)
        trial.cost = run.cost(trial.lin, run.theta + trial.x)
    decrease = cost_now - trial.cost
    run.theta = run.theta + trial.x
    step = float(np.linalg.norm(trial.x))
    run.lin = trial.lin
    rec = {"stage": stage, "iteration": it, "cost": trial.cost, "step": step, "damping": run.mu,
           "n_failed": run.lin.n_failed, "qp": trial.qp.message, "rejected": trial.rejected}
    if broyden:
        rec["jacobian"] = "broyden" if run.approximate else "model"
    run.history.append(rec)
    if callback:
        callback(rec)
    return decrease, step


def _stopped(run: _Iteration, sol: QpSolution, stop: StopRule, step: float, optimizer: str, it: int) -> None:
    """The status when the stop rule fired: converged, unless the subproblem solver gave up."""
    if sol.success or (stop.small_step(step, run.theta) and "Search_Direction_Becomes_Too_Small" in sol.message):
        # CasADi's SQP reports a vanishing search direction as a failure; at a step below the
        # tolerance that is the optimality it was asked to find (and CasadiQp accepts it at
        # larger steps when the iterate does not do worse than the start)
        run.end(EstimationStatus.CONVERGED, f"converged in {it} iterations")
    else:               # no progress because the subproblem solver gave up: not a converged estimate
        run.end(EstimationStatus.QP_FAILED, f"{optimizer} made no progress: {sol.message}")
