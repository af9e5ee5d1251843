"""The MAP's Gauss–Newton for models without exact derivatives (an FMU): Broyden's rank-one Jacobian
update (Dennis & Schnabel 1983, §8.1) against its defining properties and against the iteration with a
model Jacobian every step, and the stop at the model's noise against the minimum of the noise-free model."""

import numpy as np
import pytest

from calib.calibration.gauss_newton import EstimationStatus, StopRule, broyden_update, estimate_map
from calib.calibration.problem import LeastSquaresProblem, ProblemStatement
from calib.models.base import Capabilities, Channel, Evaluation, OperatingConditions, Parameter


class SteadyModel:
    """Two channels nonlinear in four parameters, y₁ = a e^(−b t) + c sin(d t), y₂ = a b + c d t + b² t,
    t the wind speed, with forward-difference derivatives (step ``h``) as an FMU's, and optionally
    deterministic output jumps of amplitude ``jump`` [output units] that change at parameter spacings of
    1e-4 (an inner iteration stopping one step earlier or later)."""

    def __init__(self, h=1e-6, jump=0.0):
        self.h, self.jump = h, jump
        self._params = tuple(Parameter(name, 0.0, -50.0, 50.0, 1.0) for name in "abcd")
        self._channels = (Channel("y1", "-"), Channel("y2", "-"))
        self.n_evaluations = 0

    parameters = property(lambda self: self._params)
    channels = property(lambda self: self._channels)
    capabilities = Capabilities("SteadyModel", derivatives="finite_difference")

    def _values(self, p, t):
        self.n_evaluations += 1
        a, b, c, d = np.asarray(p, float)
        y = np.stack([a * np.exp(-b * t) + c * np.sin(d * t), a * b + c * d * t + b * b * t], axis=1)
        if self.jump:
            key = np.floor(np.asarray(p) / 1e-4) @ np.array([1.0, 7.0, 13.0, 29.0])
            y = y + self.jump * np.sin(key * 12.9898 + np.arange(y.size).reshape(y.shape) * 78.233)
        return y

    def evaluate(self, p, cond):
        y = self._values(p, cond.wind_speed)
        return Evaluation(y, np.zeros(len(cond), int), ("",) * len(cond), self._channels)

    def jacobian(self, p, cond):
        p = np.asarray(p, float)
        ev = self.evaluate(p, cond)
        G = np.stack([(self._values(p + self.h * e, cond.wind_speed) - ev.values) / self.h for e in np.eye(4)], axis=2)
        return ev, G


def _problem(model, noise=0.05, n=60, seed=4):
    t = np.linspace(0.0, 3.0, n)
    cond = OperatingConditions(t, np.full(n, 10.0), np.zeros(n))
    rng = np.random.default_rng(seed)
    truth = np.array([1.5, 0.7, 0.4, 2.1])
    z = SteadyModel()._values(truth, t) + noise * rng.standard_normal((n, 2))
    p0 = np.array([1.0, 0.5, 0.3, 2.0])
    one = np.ones(4)
    statement = ProblemStatement(model.parameters, p0, one, np.full(4, -50.0), np.full(4, 50.0), one,
                                 np.ones(4, bool), (0, 1))
    return LeastSquaresProblem(model, cond, z, np.full(z.shape, noise), statement)


def test_the_update_satisfies_the_secant_condition_with_the_least_change():
    """M₊ s = Δy; M₊ v = M v for every v ⊥ s (the least change in the Frobenius norm, Theorem 8.1.1);
    rows of failed points stay zero; a linear model's exact Jacobian is left as it is."""
    rng = np.random.default_rng(1)
    n_points, n_channels, n = 5, 2, 3
    M = rng.standard_normal((n_points * n_channels, n))
    ok = np.array([True, True, False, True, True])
    M[np.repeat(~ok, n_channels)] = 0.0
    r_old, r_new = rng.standard_normal(10), rng.standard_normal(10)
    r_old[np.repeat(~ok, n_channels)] = r_new[np.repeat(~ok, n_channels)] = 0.0
    s = rng.standard_normal(n)
    M1 = broyden_update(M, r_old, r_new, s, ok, n_channels)
    np.testing.assert_allclose(M1 @ s, -(r_new - r_old), atol=1e-12)
    v = np.cross(s, rng.standard_normal(3))
    np.testing.assert_allclose(M1 @ v, M @ v, atol=1e-12)
    assert np.all(M1[np.repeat(~ok, n_channels)] == 0.0)
    A = rng.standard_normal((10, n))
    z = rng.standard_normal(10)
    p, q = rng.standard_normal(n), rng.standard_normal(n)
    np.testing.assert_allclose(broyden_update(A, z - A @ p, z - A @ q, q - p, np.ones(5, bool), 2), A, atol=1e-12)


def test_broyden_reaches_the_same_map_with_fewer_jacobians_and_ends_on_a_model_jacobian():
    """Against the iteration with a model Jacobian after every step: the same estimate within 0.01
    posterior σ, fewer model Jacobians and model calls in all, and the final linearization (the Laplace covariance's) is the
    model's forward-difference Jacobian at the estimate, not an update."""
    stop = StopRule(30, 1e-9, decrease_tolerance=5e-4)
    L = 3.0 * np.eye(4)
    runs = {}
    for broyden in (False, True):
        prob = _problem(SteadyModel())
        out = estimate_map(prob, L, None, "sqpmethod", stop, broyden=broyden)
        assert out.status == EstimationStatus.CONVERGED
        runs[broyden] = out, prob.n_jacobians, prob.model.n_evaluations
    (ref, jac_ref, sim_ref), (new, jac_new, sim_new) = runs[False], runs[True]
    assert new.broyden_updates > 0
    assert jac_new < jac_ref and sim_new < sim_ref
    J = -(ref.linearization.M @ L)
    cov_u = np.linalg.inv(J.T @ J + np.eye(4))
    du = np.linalg.solve(L, new.p - ref.p)
    assert np.max(np.abs(du) / np.sqrt(np.diag(cov_u))) < 0.01
    fresh = _problem(SteadyModel()).linearize(new.p)
    np.testing.assert_allclose(new.linearization.M, fresh.M, rtol=0, atol=1e-12 * np.max(np.abs(fresh.M)))


def test_a_noisy_model_stops_at_its_noise_near_the_smooth_minimum_with_fewer_evaluations():
    """Output jumps of 0.01 noise σ (its cost flat to them near the minimum): with ``noise_decrease``
    the iteration ends converged to the noise, within 0.1 posterior σ of the noise-free model's MAP,
    after fewer model evaluations than the damping schedule without it, which rejects step after step."""
    L = 3.0 * np.eye(4)
    smooth = estimate_map(_problem(SteadyModel()), L, None, "sqpmethod", StopRule(30, 1e-12))
    J = -(smooth.linearization.M @ L)
    sd_u = np.sqrt(np.diag(np.linalg.inv(J.T @ J + np.eye(4))))
    found = {}
    for noise_decrease in (0.0, 5e-3):
        model = SteadyModel(h=0.05, jump=0.0005)
        stop = StopRule(30, 1e-9, decrease_tolerance=5e-4, noise_decrease=noise_decrease)
        out = estimate_map(_problem(model), L, None, "sqpmethod", stop)
        found[noise_decrease] = out, model.n_evaluations
        assert np.max(np.abs(np.linalg.solve(L, out.p - smooth.p)) / sd_u) < 0.1
    (old, n_old), (new, n_new) = found[0.0], found[5e-3]
    assert new.status == EstimationStatus.CONVERGED and "noise" in new.message
    assert old.rejected > new.rejected
    assert n_new < n_old


@pytest.mark.parametrize("value", ["secant", 3])
def test_jacobian_updates_setting_is_checked(value):
    from calib.calibration.settings import CalibrationSettings
    from calib.errors import InputError
    with pytest.raises(InputError, match="jacobian_updates"):
        CalibrationSettings(jacobian_updates=value).validate("run.toml", "calibration.")


def test_the_reuse_distance_is_a_tenth_of_the_declared_difference_step():
    """1e-3 scale units when the model declares no step (and at the FMU mappings' 0.01), 0.01 at 0.1."""
    from calib.calibration.estimation_parts import JACOBIAN_REUSE_STEP, jacobian_reuse_step
    assert jacobian_reuse_step(None) == JACOBIAN_REUSE_STEP == 1e-3
    assert jacobian_reuse_step(0.01) == pytest.approx(1e-3, rel=1e-12)
    assert jacobian_reuse_step(0.1) == pytest.approx(0.01, rel=1e-12)
    assert jacobian_reuse_step(0.0) == JACOBIAN_REUSE_STEP


class DeclaredStepModel(SteadyModel):
    """:class:`SteadyModel` declaring its difference step ``h`` (scale 1: h scale units), as an FMU does."""

    capabilities = Capabilities("SteadyModel", derivatives="finite_difference", difference_step=0.05)


def test_a_declared_difference_step_keeps_the_model_jacobian_over_short_steps():
    """Forward differences of step 0.05 scale units, started 0.003 from the MAP: the step there ends within
    0.005 (a tenth of the declared step) of the model Jacobian's point and keeps that Jacobian, where the
    undeclared 1e-3 makes it a secant update and then takes a second model Jacobian before stopping. Both
    estimates within 0.1 posterior σ of the MAP with exact differences; the final linearization of the
    declared model is its model Jacobian at the start (no update)."""
    L = 3.0 * np.eye(4)
    smooth = estimate_map(_problem(SteadyModel()), L, None, "sqpmethod", StopRule(30, 1e-12))
    J = -(smooth.linearization.M @ L)
    sd_u = np.sqrt(np.diag(np.linalg.inv(J.T @ J + np.eye(4))))
    stop = StopRule(30, 1e-9, decrease_tolerance=5e-4, noise_decrease=5e-3)
    start = smooth.p + np.array([0.003, -0.002, 0.002, -0.003])
    found = {}
    for cls in (SteadyModel, DeclaredStepModel):
        prob = _problem(cls(h=0.05))
        u0 = np.linalg.solve(L, prob.scaled(start))
        out = estimate_map(prob, L, u0, "sqpmethod", stop, broyden=True)
        assert out.status == EstimationStatus.CONVERGED
        assert np.max(np.abs(np.linalg.solve(L, out.p - smooth.p)) / sd_u) < 0.1
        found[cls] = out, prob.n_jacobians
    (old, jac_old), (new, jac_new) = found[SteadyModel], found[DeclaredStepModel]
    assert old.broyden_updates >= 1 and jac_old == 2
    assert new.broyden_updates == 0 and jac_new == 1
    at_start = _problem(DeclaredStepModel(h=0.05)).linearize(start)
    # exact on purpose: the kept Jacobian is the start's own array, same code path in this process; a Broyden
    # update of it would differ by O(step) only, which a tolerance could let through
    np.testing.assert_array_equal(new.linearization.M, at_start.M)
