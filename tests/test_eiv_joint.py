"""Errors in variables, the joint estimator (issue 40 item 1) and the marginal problem's whitening
hook: each point's true conditions against a direct minimization of its joint cost, the reduced
problem's cost and gradient against the joint cost and its finite differences, the hook bit for bit
as the marginal problem's own formula, and a synthetic round trip on the global biases."""

import numpy as np
import pytest
from scipy.optimize import minimize

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.eiv_campaign import CampaignSpec, synthesize_campaign
from calib.calibration.errors_in_variables import (JointProblem, MarginalProblem, condition_sensitivities,
                                                   effective_cholesky)
from calib.calibration.problem import ProblemStatement
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import nominal_vector

CHANNELS = ("power", "thrust", "root_flap_moment")
FAST = {"prior_check": False, "tightening": False, "curvature_samples": 0}


@pytest.fixture(scope="module")
def setup():
    """NREL 5-MW with the polars known, its global biases fitted; a 10-record campaign."""
    rotor = load_rotor("nrel5mw")
    bem = BemSettings(use_tilt=False)
    model = BemModel(rotor, None, CHANNELS, bem, nuisance=("wind_scale", "pitch_offset"))
    truth = BemModel(rotor, None, CHANNELS, bem, nuisance=())
    meas, _ = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=10), seed=21)
    pars = model.parameters
    n = len(pars)
    statement = ProblemStatement(pars, nominal_vector(pars), [q.scale for q in pars], [q.lower for q in pars],
                                 [q.upper for q in pars], np.full(n, 1.0), np.ones(n, bool), tuple(range(3)))
    sigma_u = np.c_[meas.condition_sigma["wind_speed"], np.zeros(len(meas.conditions)),
                    meas.condition_sigma["pitch"]]
    return model, meas, statement, sigma_u


def joint_problem(setup):
    model, meas, statement, sigma_u = setup
    return JointProblem(model, meas.conditions, meas.values, meas.sigma, sigma_u, statement)


def test_each_points_conditions_minimize_its_joint_cost(setup):
    """δ*(p) against Nelder–Mead on each point's own joint cost ½‖(z − y(p, u + δ))/σ_y‖² + ½‖δ/σ_u‖²."""
    model, meas, statement, sigma_u = setup
    prob = joint_problem(setup)
    p = np.array([1.02, 0.3])
    state = prob.solve_conditions(p)
    assert state["settled"] and np.all(state["ok"])
    delta = state["delta"]
    assert np.all(delta[:, 1] == 0.0)                  # rotor speed without σ: not moved
    for k in (0, 4, 9):
        def cost(d, k=k):
            c = prob.shifted(np.zeros_like(delta))
            one = type(c)(c.wind_speed[[k]] + d[0], c.rotor_speed[[k]], c.pitch[[k]] + d[1], c.air_density[[k]])
            y = model.evaluate(p, one).values[0, :3]
            return 0.5 * np.sum(((meas.values[k] - y) / meas.sigma[k]) ** 2) + 0.5 * (
                (d[0] / sigma_u[k, 0]) ** 2 + (d[1] / sigma_u[k, 2]) ** 2)
        x0 = np.zeros(2)
        ref = minimize(cost, x0, method="Nelder-Mead",
                       options={"xatol": 1e-6 * sigma_u[k, 2], "fatol": 1e-12, "maxiter": 4000})
        np.testing.assert_allclose(delta[k, [0, 2]] / sigma_u[k, [0, 2]], ref.x / sigma_u[k, [0, 2]], atol=3e-3)
        assert cost(delta[k, [0, 2]]) <= ref.fun + 1e-6


def test_reduced_problem_is_the_profiled_joint_cost_and_its_gradient(setup):
    """½‖r̃‖² equals the joint cost at δ*(p), and −Mᵀ r̃ its gradient in the scaled parameters
    (central differences of the profiled cost)."""
    model, meas, statement, sigma_u = setup
    prob = joint_problem(setup)
    p = np.array([1.025, 0.4])
    lin = prob.linearize(p)
    d = prob.delta
    ev = model.evaluate(p, prob.shifted(d))
    y = ev.values[:, :3]
    su = np.where(sigma_u > 0, sigma_u, 1.0)
    joint_cost = 0.5 * np.sum(((meas.values - y) / meas.sigma) ** 2) + 0.5 * np.sum((d / su) ** 2)
    assert lin.cost == pytest.approx(joint_cost, rel=1e-5)
    grad = -lin.M.T @ lin.residual.reshape(-1)
    fd = []
    for j in range(2):
        h = 1e-4
        e = np.zeros(2)
        e[j] = h * statement.scale[j]
        fd.append((joint_problem(setup).evaluate(p + e).cost - joint_problem(setup).evaluate(p - e).cost) / (2 * h))
    np.testing.assert_allclose(grad, fd, rtol=2e-3, atol=1e-3 * np.max(np.abs(fd)))


def test_marginal_whitening_hook_is_bit_identical_to_its_formula(setup):
    """The marginal problem's sensitivities through LeastSquaresProblem.linearize's hook are, bit for
    bit, L_k⁻¹ (∂y_k/∂p · scale) with zero rows at failed points (the formula of its former copy)."""
    model, meas, statement, sigma_u = setup
    p = statement.p0 + 0.01
    J, _ = condition_sensitivities(model, p, meas.conditions, statement.channel_index, sigma_u)
    chol = effective_cholesky(meas.sigma, J, sigma_u)
    prob = MarginalProblem(model, meas.conditions, meas.values, meas.sigma, statement, chol)
    lin = prob.linearize(p)
    _, G = model.jacobian(p, meas.conditions)
    Gs = np.nan_to_num(G[:, statement.channel_index, :] * statement.scale[None, None, :], nan=0.0,
                       posinf=0.0, neginf=0.0)
    expected = np.where(lin.ok[:, None, None], np.linalg.solve(chol, Gs), 0.0).reshape(-1, G.shape[-1])
    assert np.array_equal(lin.M, expected)


def test_joint_removes_the_output_error_bias_of_the_global_biases():
    """As the marginal round trip (test_errors_in_variables.py): the polars known, a nacelle
    anemometer reading 0.97 V with 3 % scatter, the pitch 0.5 deg low with 0.2 deg scatter; the
    joint estimate's mean error within reach of its standard error, its 95 % intervals covering."""
    rotor = load_rotor("nrel5mw")
    bem = BemSettings(use_tilt=False)
    model = BemModel(rotor, None, CHANNELS, bem, nuisance=("wind_scale", "pitch_offset"))
    truth = BemModel(rotor, None, CHANNELS, bem, nuisance=())
    spec = CampaignSpec(n_records=80)
    true_p = np.array([1.0 / spec.anemometer_scale, spec.pitch_offset])
    err, oe, cover = [], [], []
    for seed in range(8):
        meas, _ = synthesize_campaign(truth, np.zeros(0), spec, seed=100 + seed)
        res = Calibrator(model, meas, CalibrationSettings(errors_in_variables="joint", **FAST)).run()
        assert res.estimate.status == "converged"
        assert "errors in variables (joint)" in res.estimate.message and "NOT settled" not in res.estimate.message
        e = res.estimate.p_hat - true_p
        err.append(e)
        cover.append(np.abs(e) <= 1.96 * res.uncertainty.std_p)
        ign = Calibrator(model, meas, CalibrationSettings(errors_in_variables="ignore", **FAST)).run()
        oe.append(ign.estimate.p_hat - true_p)
    err, oe = np.array(err), np.array(oe)
    se = err.std(axis=0, ddof=1) / np.sqrt(len(err))
    assert abs(oe[:, 0].mean()) > 3 * abs(err[:, 0].mean())
    assert np.all(np.abs(err.mean(axis=0)) < 4 * se + 1e-4)
    assert np.mean(cover) >= 0.8


def test_joint_is_a_valid_setting():
    CalibrationSettings(errors_in_variables="joint").validate()
