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
from calib.calibration.eiv_joint import JointProblem
from calib.calibration.errors_in_variables import (MarginalProblem, condition_sensitivities,
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
                    meas.condition_sigma["pitch"], np.zeros(len(meas.conditions))]
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


@pytest.fixture(scope="module")
def calibrated():
    """The global biases calibrated (joint estimator) on a 30-record campaign."""
    rotor = load_rotor("nrel5mw")
    bem = BemSettings(use_tilt=False)
    model = BemModel(rotor, None, CHANNELS, bem, nuisance=("wind_scale", "pitch_offset"))
    truth = BemModel(rotor, None, CHANNELS, bem, nuisance=())
    meas, _ = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=30), seed=5)
    res = Calibrator(model, meas, CalibrationSettings(errors_in_variables="joint", **FAST)).run()
    return model, res


def test_prediction_at_uncertain_conditions_matches_monte_carlo(calibrated):
    """The conditions' share of a prediction's variance against the sample variance of the calibrated
    model's outputs at conditions drawn about the stated ones with the stated σ; the total is the
    exact-condition variance plus that share."""
    from calib.types import OperatingConditions
    model, res = calibrated
    cond = OperatingConditions([6.0, 9.0, 14.0], [7.0, 10.5, 12.1], [0.0, 0.0, 5.0], [1.2, 1.225, 1.25])
    su = np.array([[0.18, 0.0, 0.2], [0.27, 0.1, 0.2], [0.42, 0.0, 0.3]])
    exact = res.predict(cond, model=model)
    pred = res.predict(cond, model=model, condition_sigma=su)
    assert exact.condition_std is None
    np.testing.assert_allclose(pred.std ** 2, exact.std ** 2 + pred.condition_std ** 2, rtol=1e-9)
    np.testing.assert_allclose(pred.values, exact.values)
    rng = np.random.default_rng(3)
    n = 2000
    for k in range(3):
        e = rng.standard_normal((n, 3)) * su[k]
        draws = OperatingConditions(cond.wind_speed[k] + e[:, 0], cond.rotor_speed[k] + e[:, 1],
                                    cond.pitch[k] + e[:, 2], np.full(n, cond.air_density[k]))
        y = model.evaluate(res.estimate.p_hat, draws).values[:, :3]
        # sample std of n = 2000 draws: standard error about 1.6 %; the linearization's own error a few %
        np.testing.assert_allclose(pred.condition_std[k], y.std(axis=0, ddof=1), rtol=0.08)


def test_prediction_refuses_a_negative_condition_sigma(calibrated):
    from calib.errors import InputError
    from calib.types import OperatingConditions
    model, res = calibrated
    cond = OperatingConditions([8.0], [9.0], [0.0])
    with pytest.raises(InputError, match=">= 0") as exc:
        res.predict(cond, model=model, condition_sigma=np.array([[0.1, -0.1, 0.0]]))
    assert exc.value.field == "condition_sigma"


def test_calib_predict_carries_the_data_condition_sigma(calibrated, tmp_path):
    """``calib predict`` on a table with wind_speed_sigma and pitch_sigma columns: wider intervals
    than without, by the conditions' share it prints."""
    from calib.calibration.predict_command import run_predict
    model, res = calibrated
    res.save(tmp_path / "res")
    rows = "wind_speed,rotor_speed,pitch,air_density,wind_speed_sigma,pitch_sigma\n8,9.5,0,1.225,0.24,0.2\n12,12.1,4,1.225,0.36,0.2\n"
    (tmp_path / "a.csv").write_text(rows)
    (tmp_path / "b.csv").write_text("\n".join(",".join(r.split(",")[:4]) for r in rows.splitlines()) + "\n")
    lines = []
    run_predict(tmp_path / "res", tmp_path / "a.csv", tmp_path / "a_out.csv", printer=lines.append)
    run_predict(tmp_path / "res", tmp_path / "b.csv", tmp_path / "b_out.csv", printer=lines.append)
    assert any("carry the conditions' uncertainty" in line for line in lines)
    import csv

    def widths(path):
        rows = list(csv.DictReader(line for line in open(path) if not line.startswith("#")))
        lo = [k for k in rows[0] if k.startswith("power_lower")][0]
        hi = [k for k in rows[0] if k.startswith("power_upper")][0]
        return np.array([float(r[hi]) - float(r[lo]) for r in rows])
    assert np.all(widths(tmp_path / "a_out.csv") > 1.5 * widths(tmp_path / "b_out.csv"))


def test_joint_with_zero_condition_sigma_is_the_output_error_fit(setup):
    """No condition σ stated, or all zero: the joint setting leaves the calibration the output-error fit
    (the path the bit-identical workflow test of test_errors_in_variables.py runs)."""
    import dataclasses

    from calib.calibration.errors_in_variables import uncertain_conditions
    _, meas, _, _ = setup
    zero = dataclasses.replace(meas, condition_sigma={k: np.zeros_like(v) for k, v in meas.condition_sigma.items()})
    assert uncertain_conditions(zero, CalibrationSettings(errors_in_variables="joint")) is None
    assert uncertain_conditions(meas, CalibrationSettings(errors_in_variables="joint")) is not None


def test_remembering_an_old_linearization_restores_its_factors(setup):
    """An estimator going back to a linearization older than those the problem keeps (bench_eiv seed
    4040): its conditions are solved again, its factors made current, no error."""
    prob = joint_problem(setup)
    first = prob.linearize(np.array([1.02, 0.3]))
    chol_first = prob.chol.copy()
    for k in range(34):
        prob.linearize(np.array([1.02 + 1e-4 * (k + 1), 0.3]))
    assert not np.allclose(prob.chol, chol_first, rtol=1e-9, atol=0)
    prob.remember(first)
    # solved again from another start: the same conditions to within the inner tolerance (1e-3 σ)
    np.testing.assert_allclose(prob.chol, chol_first, rtol=1e-4, atol=1e-9 * np.max(np.abs(chol_first)))
    assert prob.linearize(first.p) is first


class _KinkModel:
    """y = p·g(V) with g piecewise linear in V, its slope 1 below V = 10 m/s and 3 above (a kink like a
    node of a polar table); one channel."""

    def evaluate(self, p, conditions):
        from types import SimpleNamespace
        v = np.asarray(conditions.wind_speed, float)
        g = np.where(v < 10.0, v, 10.0 + 3.0 * (v - 10.0))
        return SimpleNamespace(values=(p[0] * g)[:, None], ok=np.ones(v.size, bool))


def test_a_point_at_a_kink_is_stationary_and_counted_not_stuck():
    """A reading whose joint cost has its minimum at the kink: the one-sided Gauss–Newton step is refused
    at every halving, the point is counted as stationary at a kink (not as NOT settled) and its δ is the
    kink's to within the settling tolerance; a smooth point beside it settles by its step size. Independent
    reference: the joint cost's minimum over a fine grid of δ."""
    from calib.calibration.eiv_joint import LATENT_SETTLED
    from calib.calibration.problem import ProblemStatement
    from calib.types import OperatingConditions, Parameter

    par = Parameter("gain", 1.0, 0.5, 2.0, 0.1)
    statement = ProblemStatement((par,), [1.0], [0.1], [0.5], [2.0], [1.0], [True], (0,))
    # point 0: read at 10.05 m/s (σ_V 0.1), output 9.992 (σ 0.05): the joint cost falls toward the kink
    # V = 10 (δ = -0.05) from both sides (slopes -1.8 and +4.6 per m/s there), so its minimum sits at it.
    # point 1: smooth, read at 7 m/s, output 7.1.
    cond = OperatingConditions(np.array([10.05, 7.0]), np.array([10.0, 10.0]), np.zeros(2))
    prob = JointProblem(_KinkModel(), cond, np.array([[9.992], [7.1]]), np.full((2, 1), 0.05),
                        np.array([[0.1, 0.0, 0.0, 0.0], [0.1, 0.0, 0.0, 0.0]]), statement)
    state = prob.solve_conditions(np.array([1.0]))
    assert state["settled"] and state["n_kink"] == 1 and state["n_refused"] == 0 and state["n_moving"] == 0
    assert prob.n_latent_not_settled == 0 and prob.n_latent_kink_points == 1
    grid = np.linspace(-0.3, 0.3, 600001)
    for k, (v0, z) in enumerate(((10.05, 9.992), (7.0, 7.1))):
        v = v0 + grid
        g = np.where(v < 10.0, v, 10.0 + 3.0 * (v - 10.0))
        cost = 0.5 * ((z - g) / 0.05) ** 2 + 0.5 * (grid / 0.1) ** 2
        assert abs(state["delta"][k, 0] - grid[np.argmin(cost)]) < 2 * LATENT_SETTLED * 0.1
