"""Constrained Gauss–Newton ML and MAP estimation: exact recovery, bounds, subspaces, the MAP as the
posterior mean of a linear model, optimizers by name."""

import numpy as np
import pytest

from calib.calibration.gauss_newton import EstimationStatus, StopRule, estimate_map, estimate_ml
from calib.calibration.problem import LeastSquaresProblem, ProblemStatement
from calib.calibration.qp import OPTIMIZERS, get_optimizer
from calib.errors import InputError
from calib.models.base import Capabilities, Channel, Evaluation, OperatingConditions, Parameter


class LinearModel:
    """y(p) = A(u) p + c(u): a ForwardModel whose ML estimate is a linear least-squares solution."""

    def __init__(self, n_params=4, n_channels=2, seed=0, fail_if_p0_above=None):
        rng = np.random.default_rng(seed)
        self.seed = seed
        self.n, self.c = n_params, n_channels
        self.W = rng.standard_normal((n_channels, n_params, 3))
        self.fail_if_p0_above = fail_if_p0_above
        self._params = tuple(Parameter(f"p{j}", 0.0, -1.0, 1.0, 0.5) for j in range(n_params))
        self._channels = tuple(Channel(f"y{i}", "-") for i in range(n_channels))

    parameters = property(lambda self: self._params)
    channels = property(lambda self: self._channels)
    capabilities = Capabilities("LinearModel", derivatives="exact")

    def _A(self, cond):
        basis = np.column_stack([np.ones(len(cond)), cond.wind_speed / 10, cond.pitch / 5])  # (k, 3)
        return np.einsum("kb,cnb->kcn", basis, self.W)

    def evaluate(self, p, cond):
        y = self._A(cond) @ np.asarray(p, float)
        status = np.zeros(len(cond), int)
        if self.fail_if_p0_above is not None and p[0] > self.fail_if_p0_above:
            status[0] = 1
            y[0] = np.nan
        msgs = tuple("failed" if s else "" for s in status)
        return Evaluation(y, status, msgs, self._channels)

    def jacobian(self, p, cond):
        return self.evaluate(p, cond), self._A(cond)


def _conditions(n=12):
    V = np.linspace(5, 12, n)
    return OperatingConditions(V, 10.0 * np.ones(n), np.tile([0.0, 2.0, 4.0], n // 3 + 1)[:n])


def _statement(model, p0, channel_index, lower=None, upper=None):
    """The statement of a problem on ``model``'s parameters: nominal ``p0``, the parameters' scales
    and bounds (unless given), a prior nobody stated (the ML estimators do not read it)."""
    qs = model.parameters
    scale = np.array([q.scale for q in qs])
    lo = np.array([q.lower for q in qs]) if lower is None else lower
    hi = np.array([q.upper for q in qs]) if upper is None else upper
    return ProblemStatement(qs, p0, scale, lo, hi, scale, np.zeros(len(qs), bool), channel_index)


def _problem(model, p_true, noise=0.0, seed=1, lower=None, upper=None):
    cond = _conditions()
    z = LinearModel(model.n, model.c, model.seed).evaluate(p_true, cond).values  # complete data, same A
    z = z + noise * np.random.default_rng(seed).standard_normal(z.shape)
    sigma = np.full(z.shape, noise if noise > 0 else 1e-3)
    statement = _statement(model, np.zeros(model.n), range(model.c), lower, upper)
    return LeastSquaresProblem(model, cond, z, sigma, statement)


@pytest.mark.parametrize("optimizer", sorted(OPTIMIZERS))
def test_noise_free_linear_problem_is_recovered_exactly(optimizer):
    model = LinearModel()
    p_true = np.array([0.3, -0.2, 0.5, 0.1])
    prob = _problem(model, p_true)
    out = estimate_ml(prob, np.eye(model.n), optimizer=optimizer)
    assert out.converged, out.message
    np.testing.assert_allclose(out.p, p_true, atol=1e-6)
    assert out.cost < 1e-6


def test_bounds_are_respected_and_active():
    model = LinearModel()
    p_true = np.array([0.3, -0.2, 0.5, 0.1])
    upper = np.array([1.0, 1.0, 0.2, 1.0])  # truth violates the bound on p2
    prob = _problem(model, p_true, upper=upper)
    out = estimate_ml(prob, np.eye(model.n), optimizer="sqpmethod")
    assert np.all(out.p <= upper + 1e-9) and np.all(out.p >= prob.statement.lower - 1e-9)
    assert out.p[2] == pytest.approx(0.2, abs=1e-7)


def test_subspace_estimate_is_the_projected_least_squares_solution():
    model = LinearModel(n_params=4, seed=3)
    p_true = np.array([0.2, 0.1, -0.3, 0.05])
    prob = _problem(model, p_true, noise=0.01)
    B = np.linalg.qr(np.random.default_rng(0).standard_normal((4, 2)))[0]
    out = estimate_ml(prob, B, optimizer="slsqp")
    # closed form: min ||(z - A p0 - A D B θ)/σ||
    lin = prob.linearize(prob.statement.p0)
    J = lin.M @ B
    theta_ls = np.linalg.lstsq(J, lin.residual.reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(out.theta, theta_ls, atol=1e-6)
    np.testing.assert_allclose(out.p, prob.p_of(B, theta_ls), atol=1e-6)


def test_progress_callback_reports_every_iteration():
    model = LinearModel()
    prob = _problem(model, np.array([0.3, -0.2, 0.5, 0.1]), noise=0.01)
    records = []
    out = estimate_ml(prob, np.eye(model.n), callback=records.append, stage="unit")
    assert len(records) == out.iterations == len(out.history)
    assert all(r["stage"] == "unit" and "cost" in r and "n_failed" in r for r in records)
    costs = [r["cost"] for r in records]
    assert all(b <= a + 1e-12 for a, b in zip(costs, costs[1:]))


def test_steps_that_make_points_fail_are_rejected():
    model = LinearModel(fail_if_p0_above=0.25)
    p_true = np.array([0.3, -0.2, 0.5, 0.1])  # the truth lies in the failing region
    prob = _problem(model, p_true)
    out = estimate_ml(prob, np.eye(model.n))
    assert out.linearization.n_failed == 0
    assert out.p[0] <= 0.25 + 1e-12
    assert prob.n_failed_points_total >= 1  # the rejected trials were counted


def test_empty_subspace_returns_nominal():
    model = LinearModel()
    prob = _problem(model, np.array([0.3, -0.2, 0.5, 0.1]))
    out = estimate_ml(prob, np.zeros((model.n, 0)))
    assert out.converged and np.array_equal(out.p, prob.statement.p0)


def test_unknown_optimizer_error_lists_valid_names():
    with pytest.raises(InputError) as err:
        get_optimizer("newton")
    msg = str(err.value)
    assert "newton" in msg and all(name in msg for name in OPTIMIZERS)


def test_a_step_leaving_the_bounds_is_cut_back_to_them():
    from calib.calibration.estimation_parts import feasible_step as _feasible_step
    B = np.eye(2)
    theta = np.array([0.5, 0.0])
    x = np.array([1.0, 0.2])  # would reach 1.5 in the first coordinate, bound 1.0
    step = _feasible_step(B, theta, x, np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    assert np.all(B @ (theta + step) <= 1.0) and np.isclose((theta + step)[0], 1.0)
    np.testing.assert_allclose(step / np.linalg.norm(step), x / np.linalg.norm(x))
    inside = np.array([0.1, -0.1])
    np.testing.assert_array_equal(_feasible_step(B, theta, inside, -np.ones(2), np.ones(2)), inside)


def test_a_round_off_step_across_an_active_bound_does_not_stop_the_step():
    """A start exactly on a bound and a QP step that crosses it by round-off (1e-17, as a QP
    solver returns along an active constraint): the step is kept, not cut to zero (which
    stopped the estimator at nominal on the coverage benchmark's twin (d))."""
    from calib.calibration.estimation_parts import feasible_step as _feasible_step
    B = np.linalg.qr(np.random.default_rng(7).standard_normal((3, 2)))[0]
    lb, ub = -np.ones(3), np.ones(3)
    theta = np.linalg.lstsq(B, np.array([-1.0, 0.2, 0.1]), rcond=None)[0]
    lb[0] = (B @ theta)[0]                                # the start is on the lower bound of p̃₀
    x = np.array([0.3, -0.2])
    x = x - B[0] * (B[0] @ x) / (B[0] @ B[0])             # a step along the bound ...
    x = x + B[0] * (-3e-17 / (B[0] @ B[0]))               # ... crossing it by round-off
    assert (B @ x)[0] < 0
    step = _feasible_step(B, theta, x, lb, ub)
    np.testing.assert_allclose(step, x)
    assert np.all(B @ (theta + step) >= lb - 1e-12)
    # a real step across the bound is still cut at it
    out = _feasible_step(B, theta, x - 0.1 * B[0], lb, ub)
    assert np.all(B @ (theta + out) >= lb - 1e-15)


def test_an_infeasible_start_is_pulled_back_inside_the_bounds():
    """A start θ₀ whose projection leaves the bounds (a new subspace after re-linearization)
    is pulled back toward nominal; the model is never asked outside its bounds."""
    calls = []

    class Box:
        parameters = (Parameter("a", 0.0, -1.0, 1.0, 1.0), Parameter("b", 0.0, -1.0, 1.0, 1.0))
        channels = (Channel("y", "-"),)
        capabilities = Capabilities("Box", derivatives="exact")

        def evaluate(self, p, cond):
            calls.append(np.array(p))
            return Evaluation(np.array([[p[0] + p[1]]] * len(cond)), np.zeros(len(cond), int), ("",) * len(cond),
                              self.channels)

        def jacobian(self, p, cond):
            assert np.all(np.abs(p) <= 1.0 + 1e-12), p
            calls.append(np.array(p))
            return self.evaluate(p, cond), np.ones((len(cond), 1, 2))

    cond = OperatingConditions([8.0], [10.0], [0.0])
    model = Box()
    problem = LeastSquaresProblem(model, cond, np.array([[0.5]]), np.array([[0.1]]),
                                  _statement(model, np.zeros(2), [0]))
    basis = np.array([[2.0], [1.0]]) / np.sqrt(5)
    # θ₀ = 3 gives (2.68, 1.34); clipped (1, 1) and projected back on the basis: (1.2, 0.6), still outside
    out = estimate_ml(problem, basis, np.array([3.0]))
    assert np.all(np.abs(out.p) <= 1.0 + 1e-12) and all(np.all(np.abs(c) <= 1.0 + 1e-12) for c in calls)


def test_an_iteration_damps_until_a_step_is_accepted_and_says_stalled_when_it_cannot(monkeypatch):
    """The full Gauss–Newton step lands where a point fails: more damping finds a step that
    does not (converged, inside the working region); with a single damping level the
    estimator stops where it started and says "stalled", not "converged"."""
    import calib.calibration.gauss_newton as est

    model = LinearModel(fail_if_p0_above=0.05)
    prob = _problem(model, np.array([0.8, -0.2, 0.5, 0.1]))
    out = estimate_ml(prob, np.eye(model.n))
    assert out.status == "converged" and out.linearization.n_failed == 0
    assert out.cost < prob.linearize(prob.statement.p0).cost
    monkeypatch.setattr(est, "DAMPING_TRIES", 1)
    stuck = estimate_ml(_problem(model, np.array([0.8, -0.2, 0.5, 0.1])), np.eye(model.n))
    assert stuck.status == "stalled" and not stuck.history and np.array_equal(stuck.p, np.zeros(model.n))


def test_sqpmethod_vanishing_search_direction_is_accepted_only_at_an_improving_point(monkeypatch):
    """CasADi's sqpmethod can end a strictly convex QP with "Search_Direction_Becomes_Too_Small"
    (a failure to CasADi) at the QP's solution: that iterate is accepted. The same status at an
    iterate worse than the start x = 0, or any other failure, is not (a coverage twin run had
    ended "failed" on it with the cost converged)."""
    from calib.calibration.qp import CasadiQp

    H = np.diag([2.0, 1.0])
    g = np.array([-2.0, 1.0])
    A, lb, ub = np.eye(2), np.array([-5.0, 0.0]), np.array([5.0, 5.0])
    exact = np.array([1.0, 0.0])                # the minimizer: x1 = 1, x2 at its bound 0

    class FakeSolver:
        def __init__(self, x, status):
            self.x, self.status = x, status

        def __call__(self, **kwargs):
            return {"x": self.x}

        def stats(self):
            return {"success": False, "return_status": self.status}

    qp = CasadiQp("sqpmethod")
    for x, status, accepted in ((exact, "Search_Direction_Becomes_Too_Small", True),
                                (np.array([3.0, 1.0]), "Search_Direction_Becomes_Too_Small", False),
                                (exact, "Maximum_Iterations_Exceeded", False)):
        monkeypatch.setattr(qp, "_solver", lambda n, m, x=x, status=status: FakeSolver(x, status))
        sol = qp(H, g, A, lb, ub)
        assert sol.success is accepted and sol.message == status
    # and the real solver on this QP
    monkeypatch.undo()
    sol = CasadiQp("sqpmethod")(H, g, A, lb, ub)
    assert sol.success and np.allclose(sol.x, exact, atol=1e-8)


class _Quadratic(LinearModel):
    """y = u + u³ with u = A p: nonlinear (so damped Gauss–Newton rejects some trial steps) and monotone in u
    (so the truth is the one minimum)."""

    def evaluate(self, p, cond):
        ev = super().evaluate(p, cond)
        return Evaluation(ev.values + ev.values ** 3, ev.status, ev.messages, self._channels)

    def jacobian(self, p, cond):
        A = self._A(cond)
        u = A @ np.asarray(p, float)
        return self.evaluate(p, cond), A * (1.0 + 3.0 * u ** 2)[..., None]


@pytest.mark.parametrize("derivatives", ["exact", "finite_difference"])
def test_damped_trials_are_evaluated_when_the_jacobian_costs_simulations(derivatives):
    """A finite-difference model's rejected trial costs one evaluation, not a Jacobian (2 n more
    simulations per point): Jacobians are taken at the start and at accepted steps only. With exact
    derivatives a trial is linearized at once (the sensitivities come with the values). Both take
    the same steps to the same estimate."""
    model = _Quadratic(seed=3)
    model.capabilities = Capabilities("Quadratic", derivatives=derivatives)
    p_true = np.array([0.6, -0.5, 0.7, 0.4])
    cond = _conditions()
    z = model.evaluate(p_true, cond).values
    prob = LeastSquaresProblem(model, cond, z, np.full(z.shape, 1e-3),
                               _statement(model, np.full(model.n, -0.9), [0, 1]))
    out = estimate_ml(prob, np.eye(model.n), np.zeros(model.n), stop=StopRule(max_iterations=60))
    assert out.converged, out.message
    np.testing.assert_allclose(out.p, p_true, atol=1e-6)
    accepted = len(out.history)
    if derivatives == "finite_difference":
        assert prob.n_jacobians == accepted + 1
        assert prob.n_evaluations > accepted          # some trials were rejected, each one evaluation
    else:
        assert prob.n_evaluations == 0 and prob.n_jacobians > accepted + 1


def test_the_map_estimate_of_a_linear_model_is_the_closed_form_posterior_mean():
    """Linear outputs, Gaussian prior p̃ = L u, u ~ N(0, I), bounds far away: the MAP in u is
    (JᵀJ + I)⁻¹ Jᵀ r₀ with J the whitened sensitivities times L and r₀ the whitened residual at
    nominal (the posterior mean of Bayesian linear regression), which the ML estimate is not."""
    model = LinearModel()
    wide = np.full(model.n, 50.0)
    prob = _problem(model, np.array([0.3, -0.2, 0.25, 0.1]), noise=0.05, lower=-wide, upper=wide)
    L = np.diag([0.2, 0.5, 1.0, 2.0]) + 0.05
    at_nominal = prob.linearize(prob.statement.p0)
    J = at_nominal.M @ L
    u_closed = np.linalg.solve(J.T @ J + np.eye(model.n), J.T @ at_nominal.residual.reshape(-1))
    out = estimate_map(prob, L, stop=StopRule(max_iterations=60))
    assert out.status == EstimationStatus.CONVERGED and out.status == "converged" and f"{out.status}" == "converged"
    np.testing.assert_allclose(out.theta, u_closed, rtol=1e-6, atol=1e-9)
    assert out.cost == pytest.approx(prob.linearize(out.p).cost + 0.5 * float(out.theta @ out.theta))
    ml = estimate_ml(prob, L, stop=StopRule(max_iterations=60))
    assert np.linalg.norm(ml.theta - u_closed) > 1e-3 * np.linalg.norm(u_closed)
