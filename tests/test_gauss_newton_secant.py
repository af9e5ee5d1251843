"""The MAP's secant curvature in the Gauss–Newton iteration: the secant condition of the structured
update (Dennis, Gay & Welsch 1981), and on a fit whose residuals' curvature makes Gauss–Newton converge
linearly the same minimum as a quasi-Newton minimizer of the exact cost, in fewer iterations."""

import numpy as np
import pytest
from scipy.optimize import minimize

from calib.calibration import gauss_newton as gn
from calib.calibration.secant import psd_part, secant_update
from calib.calibration.gauss_newton import EstimationStatus, StopRule, estimate_map
from calib.calibration.problem import LeastSquaresProblem, Linearization, ProblemStatement
from calib.models.base import Capabilities, Channel, Evaluation, OperatingConditions, Parameter


class DecayModel:
    """y(t) = a exp(−b t) + c sin(d t), t the wind speed: outputs nonlinear in b and d."""

    n = 4

    def __init__(self):
        self._params = tuple(Parameter(name, 0.0, -50.0, 50.0, 1.0) for name in "abcd")
        self._channels = (Channel("y", "-"),)

    parameters = property(lambda self: self._params)
    channels = property(lambda self: self._channels)
    capabilities = Capabilities("DecayModel", derivatives="exact")

    def _parts(self, p, cond):
        a, b, c, d = np.asarray(p, float)
        t = cond.wind_speed
        e, s, k = np.exp(-b * t), np.sin(d * t), np.cos(d * t)
        y = a * e + c * s
        G = np.stack([e, -a * t * e, s, c * t * k], axis=1)
        return y[:, None], G[:, None, :]

    def evaluate(self, p, cond):
        y, _ = self._parts(p, cond)
        return Evaluation(y, np.zeros(len(cond), int), ("",) * len(cond), self._channels)

    def jacobian(self, p, cond):
        y, G = self._parts(p, cond)
        return Evaluation(y, np.zeros(len(cond), int), ("",) * len(cond), self._channels), G


def _problem(noise=0.3, n=400, seed=3, misfit=0.2):
    """Data of a different curve plus noise large against the signal: residuals that stay large at
    the minimum, so that Σ r ∇²r is not negligible beside JᵀJ."""
    t = np.linspace(0.0, 3.0, n)
    cond = OperatingConditions(t, np.full(n, 10.0), np.zeros(n))
    rng = np.random.default_rng(seed)
    z = (1.5 * np.exp(-0.7 * t) + 0.4 * np.sin(2.1 * t) + misfit * t ** 2 + noise * rng.standard_normal(n))[:, None]
    model = DecayModel()
    qs = model.parameters
    p0 = np.array([1.0, 0.5, 0.3, 2.0])
    one = np.ones(4)
    statement = ProblemStatement(qs, p0, one, np.full(4, -50.0), np.full(4, 50.0), one, np.ones(4, bool), (0,))
    return LeastSquaresProblem(model, cond, z, np.full(z.shape, noise), statement), p0


def _lin(prob, p):
    return prob.linearize(p)


def test_the_update_satisfies_the_secant_condition_and_stays_symmetric():
    """S₊ x = (J₊ − J)ᵀ r₊ exactly (up to round-off), S₊ = S₊ᵀ, from a nonzero S as well (near the
    minimum, where the curvature along the step is positive)."""
    prob, _ = _problem()
    basis = np.eye(4)
    u_ref, _ = _exact_map(prob, basis)
    p = prob.p_of(basis, u_ref)
    x = np.array([0.05, -0.03, 0.02, 0.04])
    before, after = _lin(prob, p), _lin(prob, p + x)
    y = -(after.M.T @ after.residual.reshape(-1)) + before.M.T @ before.residual.reshape(-1) + x
    assert y @ x > 0
    J0, J1 = -(before.M @ basis), -(after.M @ basis)
    y_sharp = (J1 - J0).T @ after.residual.reshape(-1)
    rng = np.random.default_rng(0)
    A = rng.standard_normal((4, 4))
    for S in (np.zeros((4, 4)), 1e-3 * (A + A.T)):
        S1 = secant_update(S, before, after, basis, x, 1.0)
        np.testing.assert_allclose(S1, S1.T, atol=1e-14 * np.abs(S1).max())
        np.testing.assert_allclose(S1 @ x, y_sharp, rtol=1e-9, atol=1e-12 * np.abs(y_sharp).max())


def test_no_update_without_positive_curvature_or_when_points_fail():
    """yᵀx ≤ 0 (a step against the gradient change) or a change in the converged points keeps S."""
    prob, p0 = _problem()
    before = _lin(prob, p0)
    S = np.diag([1.0, 2.0, 3.0, 4.0])
    x = np.array([0.05, -0.03, 0.02, 0.04])
    after = _lin(prob, p0 + x)
    flipped = Linearization(after.p, after.residual, after.ok.copy(), after.M, after.evaluation)
    flipped.ok[0] = False
    assert secant_update(S, before, flipped, np.eye(4), x, 1.0) is S
    same = Linearization(before.p, before.residual, before.ok, before.M, before.evaluation)
    assert secant_update(S, before, same, np.eye(4), np.zeros(4), 1.0) is S     # yᵀx = 0


def test_the_psd_part_drops_only_the_negative_eigenvalues():
    Q, _ = np.linalg.qr(np.random.default_rng(1).standard_normal((5, 5)))
    w = np.array([-2.0, -0.5, 0.0, 1.0, 3.0])
    P = psd_part((Q * w) @ Q.T)
    np.testing.assert_allclose(P, (Q * np.clip(w, 0, None)) @ Q.T, atol=1e-12)


def _exact_map(prob, L, u0=None):
    """The MAP in u by BFGS on the exact cost ½‖r(p₀ + L u)‖² + ½‖u‖² (scipy, analytic gradient) from
    ``u0`` (default 0), far from the bounds: an independent minimizer."""

    def f(u):
        lin = prob.linearize(prob.p_of(L, u))
        r = lin.residual.reshape(-1)
        J = -(lin.M @ L)
        return 0.5 * float(r @ r + u @ u), J.T @ r + u

    start = np.zeros(L.shape[1]) if u0 is None else u0
    res = minimize(f, start, jac=True, method="BFGS", options={"gtol": 1e-8, "maxiter": 2000})
    assert np.linalg.norm(res.jac) < 1e-4, res.message      # stationary (BFGS may stop on round-off)
    return res.x, res.fun


def test_the_secant_map_finds_the_same_minimum_in_fewer_iterations():
    """A misfit that leaves large residuals: Gauss–Newton alone (the secant switched off) converges
    linearly, in 58 iterations; the MAP with the secant curvature reaches the same minimum in far fewer.
    The minimum is checked by BFGS on the exact cost (started from Gauss–Newton's estimate, as the
    cost has another basin): the estimate within 0.01 posterior σ and the cost within the stop rule."""
    prob, _ = _problem(misfit=0.5)
    L = np.diag([2.0, 1.0, 2.0, 1.0])
    stop = StopRule(max_iterations=200, decrease_tolerance=1e-6)
    out = estimate_map(prob, L, stop=stop)
    plain = gn._gauss_newton(prob, L, None, "sqpmethod", stop, None, "map", prior_weight=1.0, secant=False)
    assert out.status == EstimationStatus.CONVERGED and plain.status == EstimationStatus.CONVERGED
    u_ref, cost_ref = _exact_map(prob, L, plain.theta)
    J = -(prob.linearize(prob.p_of(L, u_ref)).M @ L)
    sigma_u = np.sqrt(np.diag(np.linalg.inv(J.T @ J + np.eye(4))))
    for est in (out, plain):
        assert np.max(np.abs(est.theta - u_ref) / sigma_u) < 0.01
        assert est.cost == pytest.approx(cost_ref, abs=1e-4)     # ½ (0.01 σ)² in each of 4 directions: 2e-4
    assert 2 * out.iterations < plain.iterations


def test_a_failing_subproblem_with_the_secant_curvature_hands_over_to_gauss_newton(monkeypatch):
    """The first subproblem that carries a secant curvature fails (no finite step): the iteration goes
    on with Gauss–Newton's model instead of stopping as ``qp_failed``, and ends at the same minimum."""
    from calib.calibration.qp import QpSolution, get_optimizer

    prob, _ = _problem(misfit=0.5)
    L = np.diag([2.0, 1.0, 2.0, 1.0])
    stop = StopRule(max_iterations=200, decrease_tolerance=1e-6)
    reference = estimate_map(prob, L, stop=stop)
    state = {"armed": False, "failed": 0}
    psd = gn.psd_part

    def spy_psd(S):
        out = psd(S)
        state["armed"] = state["armed"] or (bool(np.any(out)) and not state["failed"])
        return out

    real = get_optimizer("sqpmethod")

    def flaky(*args):
        if state["armed"]:
            state["armed"], state["failed"] = False, state["failed"] + 1
            return QpSolution(np.full(args[0].shape[0], np.nan), False, "made to fail")
        return real(*args)

    monkeypatch.setattr(gn, "psd_part", spy_psd)
    monkeypatch.setattr(gn, "get_optimizer", lambda name: flaky)
    out = estimate_map(prob, L, stop=stop)
    assert state["failed"] == 1
    assert out.status == EstimationStatus.CONVERGED
    J = -(prob.linearize(out.p).M @ L)
    sigma_u = np.sqrt(np.diag(np.linalg.inv(J.T @ J + np.eye(4))))
    assert np.max(np.abs(out.theta - reference.theta) / sigma_u) < 0.01
