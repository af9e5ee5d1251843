r"""Errors in variables, the *joint* estimator: each point's true operating conditions estimated beside
the parameters, the measured ones their priors, eliminated point by point (:class:`JointProblem`,
:func:`fit_joint`), and the choice of estimator (:func:`fit_errors_in_variables`). The marginal
estimator and the pieces both use (the conditions' σ and sensitivities, the effective covariance's
factors) are in :mod:`calib.calibration.errors_in_variables`.

References
----------
P.T. Boggs, R.H. Byrd, R.B. Schnabel, A stable and efficient algorithm for nonlinear orthogonal
distance regression, SIAM J. Sci. Stat. Comput. 8 (1987) 1052-1078.
C. Wang, F. Campagnolo, C.L. Bottasso, Identification of airfoil polars from uncertain
experimental measurements, Wind Energ. Sci. 5 (2020) 1537-1550.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib.calibration.errors_in_variables import (MarginalProblem, condition_sensitivities, effective_cholesky,
                                                   fit_marginal)
from calib.calibration.problem import LeastSquaresProblem, Linearization
from calib.calibration.settings import UNCERTAIN_CONDITIONS
from calib.types import OperatingConditions

#: The joint estimator's inner Gauss–Newton on each point's true conditions has settled when every
#: point's last step is below this fraction of the condition's σ [-].
LATENT_SETTLED = 1e-3
#: Most inner Gauss–Newton steps per solve of the points' true conditions.
MAX_LATENT_ITERATIONS = 20
#: Most step halvings of a point whose inner step raised its cost.
MAX_LATENT_HALVINGS = 8
#: A point whose Gauss–Newton step raised its cost at every halving, down to the smallest fraction
#: tried (``LATENT_SMALLEST_STEP`` of the step), while that fraction of the step is below
#: ``LATENT_SETTLED`` σ, sits at a *kink* of the model's outputs in its conditions (a node of the
#: piecewise-linear polar tables or correction field, where ∂y/∂u jumps and the one-sided step
#: overshoots): it is stationary along its step to within the settling tolerance and counts as
#: settled (counted apart). A refused step larger than that leaves the point stuck: NOT settled.
LATENT_SMALLEST_STEP = 0.5 ** (MAX_LATENT_HALVINGS - 1)


class JointProblem(MarginalProblem):
    r"""The joint errors-in-variables problem, each point's true conditions eliminated point by point.

    The joint cost of the parameters p and the points' condition errors δ_k (true = measured + δ_k,
    measured ones the prior: δ_k ~ N(0, Σ_u,k)) is

    .. math::  J(p, δ) = ½ Σ_k ‖R_k^{-½}(z_k − y_k(p, u_k + δ_k))‖² + ½ Σ_k δ_kᵀ Σ_{u,k}^{-1} δ_k.

    For a given p each point's δ_k*(p) minimizes its own term (a Gauss–Newton on 3 unknowns per
    point, vectorized over points: δ ← Σ_u J_uᵀ C⁻¹ (z − y + J_u δ), step halved per point where its
    cost rises). Linearized in (p, δ) about (p, δ*), the Schur complement of the δ-blocks of the
    Gauss–Newton normal equations leaves the problem in p alone with, per point,

    .. math::  r̃_k = L_k⁻¹ (z_k − y_k(p, u_k + δ_k*) + J_{u,k} δ_k*),\qquad M_k = L_k⁻¹ G_k D,

    C_k = R_k + J_u,k Σ_u,k J_u,kᵀ = L_k L_kᵀ with J_u,k and G_k at the estimated true conditions
    u_k + δ_k*: the marginal problem's form, re-linearized at every parameter vector and at the
    estimated conditions instead of the measured ones. At δ* the identities C⁻¹(r + J_u δ*) = R⁻¹ r
    and ½‖r̃‖² = J(p, δ*(p)) hold, so the estimators' Gauss–Newton (MAP or truncated) runs on the
    joint cost profiled over δ, its gradient exact, its Hessian the Schur complement
    Gᵀ C⁻¹ G (the Laplace covariance of p with the conditions integrated out). The cost is linear
    in the number of points.

    Parameters
    ----------
    model, conditions, measured, statement
        As :class:`calib.calibration.problem.LeastSquaresProblem` (``conditions`` as measured).
    sigma_y : ndarray, shape (n_points, n_channels)
        Output 1-σ [channel units], > 0.
    sigma_u : ndarray, shape (n_points, 4)
        The conditions' 1-σ (:func:`condition_sigma`) [m/s, rpm, deg, kg/m³].

    Attributes
    ----------
    delta : ndarray, shape (n_points, 4)
        The estimated condition errors δ* at the last solve [m/s, rpm, deg, kg/m³].
    n_latent_solves, n_latent_not_settled, n_latent_halvings, n_failed_differences : int
        Solves of the points' conditions, those that did not settle (a point still moving after
        ``MAX_LATENT_ITERATIONS`` steps, or stuck: its step refused at every halving while its
        smallest tried fraction is above ``LATENT_SETTLED`` σ), points whose step was halved (summed over steps), and the largest
        count of points whose J_u failed.
    n_latent_kink_points, n_latent_kink_solves : int
        Points (summed over solves) stationary at a kink of the outputs (``LATENT_SMALLEST_STEP``), and
        the solves with at least one; such a solve counts as settled.
    n_latent_refused_points, n_latent_moving_points : int
        Points (summed over solves) stuck, and still moving at the step limit.

    References
    ----------
    W.H. Press et al., Numerical Recipes, 3rd ed. (2007), §15.3 (straight-line data with errors in
    both coordinates); P.T. Boggs, R.H. Byrd, R.B. Schnabel, A stable and efficient algorithm for
    nonlinear orthogonal distance regression, SIAM J. Sci. Stat. Comput. 8 (1987) 1052-1078 (the
    per-point elimination of the latent conditions); C. Wang, F. Campagnolo, C.L. Bottasso (2020).
    """

    def __init__(self, model, conditions: OperatingConditions, measured: np.ndarray, sigma_y: np.ndarray,
                 sigma_u: np.ndarray, statement):
        sigma_y = np.asarray(sigma_y, float)
        chol = np.zeros(sigma_y.shape + (sigma_y.shape[1],))
        chol[:, np.arange(sigma_y.shape[1]), np.arange(sigma_y.shape[1])] = sigma_y
        super().__init__(model, conditions, measured, sigma_y, statement, chol)
        self.sigma_u = np.asarray(sigma_u, float)
        self.delta = np.zeros_like(self.sigma_u)
        self.n_latent_solves = 0
        self.n_latent_not_settled = 0
        self.n_latent_kink_points = 0
        self.n_latent_kink_solves = 0
        self.n_latent_refused_points = 0
        self.n_latent_moving_points = 0
        self.n_latent_halvings = 0
        self.n_failed_differences = 0
        self._latent = None      # (p, state) of the last solve
        self._factors = {}       # id(linearization) -> (linearization, its solve's state)

    # ---------------------------------------------------------------- the points' true conditions
    def shifted(self, delta: np.ndarray) -> OperatingConditions:
        """The conditions measured + ``delta`` (columns :data:`UNCERTAIN_CONDITIONS`)."""
        c = self.conditions
        return replace(c, **{name: getattr(c, name) + delta[:, j] for j, name in enumerate(UNCERTAIN_CONDITIONS)
                             if np.any(delta[:, j] != 0.0)})

    def _point_costs(self, delta: np.ndarray, ev):
        """Outputs, converged points and each point's joint cost at ``delta``."""
        y = ev.values[:, self.statement.channel_index]
        ok = ev.ok & np.all(np.isfinite(y), axis=1)
        r = np.where(ok[:, None], (self.measured - np.where(ok[:, None], y, 0.0)) / self.sigma_y, 0.0)
        su = np.where(self.sigma_u > 0, self.sigma_u, 1.0)
        cost = 0.5 * np.sum(r ** 2, axis=1) + 0.5 * np.sum((delta / su) ** 2, axis=1)
        return y, ok, cost

    def _evaluate_at(self, p, delta):
        ev = self.model.evaluate(p, self.shifted(delta))
        self.n_evaluations += 1
        return (ev, *self._point_costs(delta, ev))

    def _line_search(self, p, delta, step, cost, moving):
        """The points' steps, halved per point where the cost would rise (at most
        ``MAX_LATENT_HALVINGS`` tries): ((δ, evaluation, outputs, ok, cost) at the conditions taken,
        the points whose every try was refused)."""
        lam = np.ones(len(delta))
        todo = moving.copy()
        new_delta = delta.copy()
        for halving in range(MAX_LATENT_HALVINGS):
            trial = np.where(todo[:, None], delta + lam[:, None] * step, delta)
            ev_t, y_t, ok_t, cost_t = self._evaluate_at(p, trial)
            better = todo & ok_t & (cost_t <= cost * (1.0 + 1e-12) + 1e-12)
            new_delta[better] = trial[better]
            todo &= ~better
            if not np.any(todo):
                break
            lam[todo] *= 0.5
        self.n_latent_halvings += int(np.count_nonzero(lam < 1.0))
        if halving == 0 and np.array_equal(new_delta, trial):
            return (new_delta, ev_t, y_t, ok_t, cost_t), todo      # the full step taken everywhere
        # steps halved, or refused, at some points: the outputs at the conditions taken
        return (new_delta, *self._evaluate_at(p, new_delta)), todo

    def solve_conditions(self, p: np.ndarray) -> dict:
        """δ*(p): each point's condition errors minimizing its joint cost at ``p`` (class docstring),
        started from the last solve's; with the evaluation, J_u and C_k's Cholesky factors there.

        Returns
        -------
        dict
            ``delta`` (n_points, 4), ``evaluation``, ``J_u`` (n_points, n_channels, 4), ``chol``,
            ``ok`` (points converged at their estimated conditions), ``settled``, ``iterations``,
            ``n_kink``, ``n_refused``, ``n_moving`` (points stationary at a kink, stuck, still
            moving at the step limit).
        """
        p = np.asarray(p, float)
        if self._latent is not None and np.array_equal(self._latent[0], p):
            return self._latent[1]
        active_u = self.sigma_u > 0
        su2 = self.sigma_u ** 2
        delta = np.where(active_u, self.delta, 0.0)
        ev, y, ok, cost = self._evaluate_at(p, delta)
        if np.any(~ok & np.any(delta != 0.0, axis=1)):     # a warm start where the model fails: from the reading
            delta[~ok] = 0.0
            ev, y, ok, cost = self._evaluate_at(p, delta)
        scale_u = np.where(active_u, self.sigma_u, 1.0)
        kink = np.zeros(len(delta), bool)       # refused at every halving, stationary to LATENT_SETTLED σ
        refused = np.zeros(len(delta), bool)    # refused at every halving, a larger smallest step: stuck
        it = 0
        for it in range(MAX_LATENT_ITERATIONS + 1):
            J, n_failed = condition_sensitivities(self.model, p, self.shifted(delta), self.statement.channel_index,
                                                  self.sigma_u)
            self.n_evaluations += 2 * int(np.count_nonzero(np.any(active_u, axis=0)))
            self.n_failed_differences = max(self.n_failed_differences, n_failed)
            chol = effective_cholesky(self.sigma_y, J, self.sigma_u)
            b = np.where(ok[:, None], self.measured - np.where(ok[:, None], y, 0.0), 0.0) + np.einsum("kcu,ku->kc", J, delta)
            w = np.linalg.solve(chol, b[..., None])                        # L⁻¹ b
            Cinv_b = np.linalg.solve(np.swapaxes(chol, 1, 2), w)[..., 0]   # C⁻¹ b
            target = np.where(ok[:, None], su2 * np.einsum("kcu,kc->ku", J, Cinv_b), delta)
            step = target - delta
            move = np.max(np.abs(step) / scale_u, axis=1)
            # points are independent given p: one that settled, or whose step is refused at every
            # halving (the same step again at the same δ), stays where it is
            moving = ok & ~kink & ~refused & (move >= LATENT_SETTLED)
            if not np.any(moving) or it == MAX_LATENT_ITERATIONS:
                break
            (delta, ev, y, ok, cost), todo = self._line_search(p, delta, step, cost, moving)
            at_kink = move * LATENT_SMALLEST_STEP < LATENT_SETTLED
            kink |= todo & at_kink
            refused |= todo & ~at_kink
        n_moving, n_refused, n_kink = int(np.count_nonzero(moving)), int(np.count_nonzero(refused)), \
            int(np.count_nonzero(kink))
        settled = not (n_moving or n_refused)
        self.n_latent_solves += 1
        self.n_latent_not_settled += int(not settled)
        self.n_latent_kink_points += n_kink
        self.n_latent_kink_solves += int(n_kink > 0)
        self.n_latent_refused_points += n_refused
        self.n_latent_moving_points += n_moving
        self.delta = delta
        state = {"delta": delta, "evaluation": ev, "J_u": J, "chol": chol, "ok": ok, "settled": settled,
                 "iterations": it, "n_kink": n_kink, "n_refused": n_refused, "n_moving": n_moving}
        self._latent = (p.copy(), state)
        return state

    # ---------------------------------------------------------------- the reduced problem in p
    def _reduced_residual(self, y, ok, state):
        b = self.measured - np.where(ok[:, None], y, 0.0) + np.einsum("kcu,ku->kc", state["J_u"], state["delta"])
        r = np.linalg.solve(state["chol"], np.where(ok[:, None], b, 0.0)[..., None])[..., 0]
        self.n_failed_points_total += int(np.count_nonzero(~ok))
        return np.where(ok[:, None], r, 0.0)

    def evaluate(self, p: np.ndarray) -> Linearization:
        """The profiled joint cost's whitened residuals at ``p`` (the points' conditions solved), no
        sensitivities."""
        p = np.asarray(p, float)
        if self._cache is not None and np.array_equal(self._cache.p, p):
            return self._cache
        state = self.solve_conditions(p)
        ev = state["evaluation"]
        y = ev.values[:, self.statement.channel_index]
        ok = state["ok"]
        return Linearization(p.copy(), self._reduced_residual(y, ok, state), ok, None, ev)

    def linearize(self, p: np.ndarray) -> Linearization:
        """Whitened residuals and the Schur-reduced sensitivities L_k⁻¹ ∂y_k/∂p̃ at ``p`` and the points'
        estimated true conditions (cached)."""
        p = np.asarray(p, float)
        if self._cache is not None and self._cache.M is not None and np.array_equal(self._cache.p, p):
            self._use_factors(self._cache)
            return self._cache
        state = self.solve_conditions(p)
        ev, G = self.model.jacobian(p, self.shifted(state["delta"]))
        self.n_jacobians += 1
        y = ev.values[:, self.statement.channel_index]
        ok = state["ok"] & ev.ok & np.all(np.isfinite(y), axis=1)
        self.chol = state["chol"]
        r = self._reduced_residual(y, ok, state)
        self._cache = Linearization(p.copy(), r, ok, self._whitened_sensitivities(G, ok), ev)
        self._factors[id(self._cache)] = (self._cache, state)
        while len(self._factors) > 32:           # the linearizations an estimator may go back to
            self._factors.pop(next(iter(self._factors)))
        self._use_factors(self._cache)
        return self._cache

    def _use_factors(self, lin: Linearization) -> None:
        """Make the effective covariances and the conditions at ``lin`` the current ones (solved again
        at its parameters if it is no longer among the last linearizations kept)."""
        kept = self._factors.get(id(lin))
        state = kept[1] if kept is not None and kept[0] is lin else self.solve_conditions(lin.p)
        self.chol, self.delta = state["chol"], state["delta"]
        self.sigma = np.sqrt(np.einsum("kcd,kcd->kc", self.chol, self.chol))

    def remember(self, lin: Linearization) -> None:
        """Make ``lin``, a linearization of this problem computed earlier, the cached one (its
        effective covariances and estimated conditions the current ones)."""
        super().remember(lin)
        self._use_factors(lin)


def fit_joint(cal, problem: LeastSquaresProblem, sigma_u: np.ndarray, p: np.ndarray):
    """The joint estimator: one fit of the profiled joint problem (:class:`JointProblem`).

    Parameters and returns as :func:`calib.calibration.errors_in_variables.fit_marginal`.
    """
    m = cal.measurements
    joint = JointProblem(cal.model, m.conditions, m.values, problem.sigma, sigma_u, cal.statement)
    joint.n_evaluations, joint.n_jacobians = problem.n_evaluations, problem.n_jacobians
    joint.n_failed_points_total = problem.n_failed_points_total
    fit = cal.fitter.fit(joint, p)
    text = f"errors in variables (joint): the points' true conditions solved {joint.n_latent_solves} time(s), "
    if not joint.n_latent_not_settled:
        text += "every solve settled"
    else:
        text += (f"{joint.n_latent_not_settled} NOT settled ({joint.n_latent_refused_points} point(s) stuck: "
                 f"step refused at every halving; {joint.n_latent_moving_points} still moving after "
                 f"{MAX_LATENT_ITERATIONS} steps)")
    if joint.n_latent_kink_points:
        text += (f"; in {joint.n_latent_kink_solves} solve(s) {joint.n_latent_kink_points} point(s) stationary at a "
                 f"kink of the outputs (step refused at every halving down to {LATENT_SMALLEST_STEP:g} of it, "
                 f"below {LATENT_SETTLED:g} σ)")
    if joint.n_failed_differences:
        text += (f"; the conditions' sensitivities failed at {joint.n_failed_differences} point(s) "
                 "(condition scatter left out there)")
    cal.emit({"stage": "errors_in_variables", "estimator": "joint", "iteration": 1,
              "latent_solves": joint.n_latent_solves, "latent_not_settled": joint.n_latent_not_settled,
              "latent_halvings": joint.n_latent_halvings, "latent_kink_points": joint.n_latent_kink_points,
              "latent_refused_points": joint.n_latent_refused_points,
              "latent_moving_points": joint.n_latent_moving_points,
              "n_failed_differences": joint.n_failed_differences, "status": fit.status})
    return joint, fit, f"{fit.message}; {text}" if fit.message else text


def fit_errors_in_variables(cal, problem: LeastSquaresProblem, sigma_u: np.ndarray, p: np.ndarray):
    """The estimator ``errors_in_variables`` names: :func:`fit_joint` or
    :func:`calib.calibration.errors_in_variables.fit_marginal`."""
    if cal.settings.errors_in_variables == "joint":
        return fit_joint(cal, problem, sigma_u, p)
    return fit_marginal(cal, problem, sigma_u, p)
