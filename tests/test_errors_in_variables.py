"""Errors in variables (issue 40 item 1): condition σ read and checked, the marginal estimator's
effective covariance against Monte Carlo, zero condition σ leaving a shipped workflow bit for bit
as it was, and a synthetic round trip in which the marginal estimator removes the output-error
bias of the global biases."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.eiv_campaign import R_DRY_AIR, CampaignSpec, synthesize_campaign, true_conditions
from calib.calibration.errors_in_variables import (condition_sensitivities, condition_sigma, effective_cholesky)
from calib.errors import InputError
from calib.measurements import read_measurements
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector
from calib.workflow import run_workflow

WORKFLOWS = Path(__file__).resolve().parents[1] / "workflows"
CHANNELS = ("power", "thrust", "root_flap_moment")
FAST = {"prior_check": False, "tightening": False, "curvature_samples": 0}


@pytest.fixture(scope="module")
def globals_model():
    """NREL 5-MW with the polars known: the global biases (wind scale, pitch offset) alone."""
    rotor = load_rotor("nrel5mw")
    bem = BemSettings(use_tilt=False)
    return (BemModel(rotor, None, CHANNELS, bem, nuisance=("wind_scale", "pitch_offset")),
            BemModel(rotor, None, CHANNELS, bem, nuisance=()))


def write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_condition_sigma_columns_are_read_in_their_units(tmp_path):
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power [kW],wind_speed_sigma [km/h],pitch_sigma [rad]\n"
                           "8,10,0,1500,3.6,0.01\n9,11,0,2000,0,0.02\n")
    m = read_measurements(path)
    np.testing.assert_allclose(m.condition_sigma["wind_speed"], [1.0, 0.0])
    np.testing.assert_allclose(m.condition_sigma["pitch"], np.degrees([0.01, 0.02]))
    assert "rotor_speed" not in m.condition_sigma
    assert any("condition uncertainty read" in n for n in m.notes)
    # without the columns nothing changes
    assert read_measurements(write(tmp_path, "wind_speed,rotor_speed,pitch,power\n8,10,0,1.5e6\n",
                                   "n.csv")).condition_sigma is None


def test_negative_condition_sigma_names_file_line_and_column(tmp_path):
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power,rotor_speed_sigma\n8,10,0,1.5e6,0.1\n"
                           "9,11,0,2e6,-0.1\n")
    with pytest.raises(InputError) as exc:
        read_measurements(path)
    e = exc.value
    assert e.source == str(path) and e.line == 3 and e.field == "rotor_speed_sigma"
    assert "column 5" in e.message and ">= 0" in e.message


@pytest.mark.parametrize("settings, field", [
    ({"condition_sigma": {"wind_speed": -0.1}}, "condition_sigma.wind_speed"),
    ({"condition_relative_sigma": {"pitch": float("nan")}}, "condition_relative_sigma.pitch"),
    ({"condition_sigma": {"yaw": 1.0}}, "condition_sigma.yaw"),
    ({"errors_in_variables": "orthogonal"}, "errors_in_variables"),
    ({"max_eiv_iterations": 0}, "max_eiv_iterations"),
])
def test_bad_condition_settings_name_the_key(settings, field):
    with pytest.raises(InputError) as exc:
        CalibrationSettings(**settings).validate()
    assert exc.value.field == field


def test_condition_sigmas_add_in_quadrature():
    cond = OperatingConditions([5.0, 10.0], [9.0, 12.0], [0.0, 2.0])
    from calib.measurements import Measurements
    m = Measurements(cond, ("power",), [[1.0], [2.0]], condition_sigma={"wind_speed": [0.3, 0.0]})
    s = CalibrationSettings(condition_sigma={"wind_speed": 0.4, "pitch": 0.2},
                            condition_relative_sigma={"rotor_speed": 0.01})
    sig = condition_sigma(m, s)
    np.testing.assert_allclose(sig[:, 0], [0.5, 0.4])
    np.testing.assert_allclose(sig[:, 1], [0.09, 0.12])
    np.testing.assert_allclose(sig[:, 2], [0.2, 0.2])
    assert condition_sigma(m, CalibrationSettings(condition_sigma={"pitch": 0.0})) is not None  # table's σ
    m0 = dataclasses.replace(m, condition_sigma={"wind_speed": [0.0, 0.0]})
    assert condition_sigma(m0, CalibrationSettings(condition_sigma={"pitch": 0.0})) is None


def test_effective_covariance_matches_monte_carlo(globals_model):
    """C_k = R_k + J_u Σ_u J_uᵀ against the sample covariance of the model's outputs under drawn
    condition errors (small errors: the linearization's own regime), channels of one point correlated."""
    model, _ = globals_model
    p = nominal_vector(model.parameters)
    cond = OperatingConditions([7.0, 13.0], [9.0, 12.1], [0.0, 6.0])
    idx = list(range(len(CHANNELS)))
    sigma_u = np.array([[0.07, 0.0, 0.1, 0.0], [0.13, 0.0, 0.1, 0.0]])
    J, n_failed = condition_sensitivities(model, p, cond, idx, sigma_u)
    assert n_failed == 0 and np.all(J[:, :, 1] == 0.0)
    sigma_y = 1e-3 * np.abs(model.evaluate(p, cond).values[:, idx])
    L = effective_cholesky(sigma_y, J, sigma_u)
    C = L @ np.swapaxes(L, 1, 2) - np.stack([np.diag(s ** 2) for s in sigma_y])   # the conditions' share
    rng = np.random.default_rng(7)
    n = 400
    for k in range(2):
        e = rng.standard_normal((n, 4)) * sigma_u[k]
        draws = OperatingConditions(cond.wind_speed[k] + e[:, 0], np.full(n, cond.rotor_speed[k]),
                                    cond.pitch[k] + e[:, 2])
        y = model.evaluate(p, draws).values[:, idx]
        S = np.cov(y.T)
        # sample covariance of n draws: relative standard error about sqrt(2/n) = 7 %
        scale = np.sqrt(np.outer(np.diag(C[k]), np.diag(C[k])))
        np.testing.assert_allclose(S / scale, C[k] / scale, atol=0.2)
        corr = C[k] / scale
        assert np.max(np.abs(corr - np.eye(3))) > 0.5       # a full block, not a diagonal


def test_zero_condition_sigma_leaves_a_shipped_workflow_bit_identical(tmp_path):
    """The in-family twins unchanged when every condition σ is zero, under the default estimator (the
    workflow states none: ``errors_in_variables`` is the default, ``joint``)."""
    text = (WORKFLOWS / "wind_tunnel_hub_loads.toml").read_text()
    assert "[calibration]\n" in text and "errors_in_variables" not in text
    assert CalibrationSettings().errors_in_variables == "joint"
    zero = text.replace("[calibration]\n", "[calibration]\ncondition_sigma = {wind_speed = 0.0, pitch = 0.0}\n")
    a = tmp_path / "a.toml"
    b = tmp_path / "b.toml"
    a.write_text(text)
    b.write_text(zero)
    [ra] = run_workflow(a, tmp_path / "a", progress=False, history=False)
    [rb] = run_workflow(b, tmp_path / "b", progress=False, history=False)
    assert np.array_equal(ra.result.estimate.p_hat, rb.result.estimate.p_hat)
    assert np.array_equal(ra.result.uncertainty.cov_p, rb.result.uncertainty.cov_p)
    assert "errors in variables" not in rb.result.estimate.message


def test_ml_noise_with_condition_sigma_is_refused(globals_model):
    model, truth = globals_model
    meas, _ = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=12), seed=1)
    with pytest.raises(InputError, match="state the output noise") as exc:
        Calibrator(model, meas, CalibrationSettings(noise="ml", **FAST)).run()
    assert exc.value.field == "calibration.noise"
    # ignored on request: the output-error fit runs
    res = Calibrator(model, meas, CalibrationSettings(noise="ml", errors_in_variables="ignore", **FAST)).run()
    assert res.estimate.status == "converged"


def test_campaign_density_is_the_ideal_gas_law():
    cond = true_conditions(CampaignSpec(n_records=50), 63.0, np.random.default_rng(0))
    # 268-298 K at about 1013 hPa: 1.18-1.32 kg/m^3 (dry air, R_d = 287.05 J/(kg K))
    assert R_DRY_AIR == 287.05
    assert np.all((cond.air_density > 101_325 * 0.97 / (R_DRY_AIR * 298)) &
                  (cond.air_density < 101_325 * 1.03 / (R_DRY_AIR * 268)))


def test_marginal_removes_the_output_error_bias_of_the_global_biases(globals_model):
    """Synthetic round trip (the polars known): a nacelle anemometer reading 0.97 V with 3 % scatter,
    the pitch read 0.5 deg low with 0.2 deg scatter. Over replicates the output-error estimate of the
    wind scale is biased low by several standard errors (the scatter of V through P ∝ V³); the
    marginal estimate's mean error is within its standard error's reach, and its 95 % intervals
    cover the truth."""
    model, truth = globals_model
    spec = CampaignSpec(n_records=80)
    true_k = 1.0 / spec.anemometer_scale
    err = {"ignore": [], "marginal": []}
    cover = []
    for seed in range(8):
        meas, _ = synthesize_campaign(truth, np.zeros(0), spec, seed=100 + seed)
        for mode in err:
            res = Calibrator(model, meas, CalibrationSettings(errors_in_variables=mode, **FAST)).run()
            assert res.estimate.status == "converged"
            e = res.estimate.p_hat - [true_k, spec.pitch_offset]
            err[mode].append(e)
            if mode == "marginal":
                cover.append(np.abs(e) <= 1.96 * res.uncertainty.std_p)
                assert "errors in variables (marginal)" in res.estimate.message
    oe, mg = np.array(err["ignore"]), np.array(err["marginal"])
    se = mg.std(axis=0, ddof=1) / np.sqrt(len(mg))
    assert abs(oe[:, 0].mean()) > 3 * abs(mg[:, 0].mean())
    assert abs(oe[:, 0].mean()) > 5 * oe[:, 0].std(ddof=1) / np.sqrt(len(oe))   # the bias is real
    assert np.all(np.abs(mg.mean(axis=0)) < 4 * se + 1e-4)
    assert np.mean(cover) >= 0.8


def test_field_scada_workflow_runs_with_errors_in_variables(tmp_path):
    """The shipped field workflow (docs/user_guide/field_data.md): the joint fit settles, its χ² is
    that of the stated noise, the known truth of the synthetic export (wind_scale 1/0.97, pitch offset
    0.5 deg; workflows/data/make_field_scada_csv.py) lies within the intervals, and the same
    workflow without errors in variables misfits by the conditions' scatter."""
    [stage] = run_workflow(WORKFLOWS / "field_scada.toml", tmp_path / "eiv", progress=False, history=False)
    res = stage.result
    assert res.estimate.status == "converged"
    assert "errors in variables (joint)" in res.estimate.message and "NOT settled" not in res.estimate.message
    assert res.fit.chi2_after / res.dof < 1.5
    names = [q["name"] for q in res.parameters]
    for name, truth, k in (("wind_scale", 1.0 / 0.97, 2.0), ("pitch_offset", 0.5, 3.0)):
        j = names.index(name)
        assert abs(res.estimate.p_hat[j] - truth) < k * res.uncertainty.std_p[j], name
    text = (WORKFLOWS / "field_scada.toml").read_text().replace('errors_in_variables = "joint"',
                                                                   'errors_in_variables = "ignore"')
    assert 'errors_in_variables = "ignore"' in text
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "field_scada.csv").write_bytes((WORKFLOWS / "data" / "field_scada.csv").read_bytes())
    (tmp_path / "oe.toml").write_text(text)
    [oe] = run_workflow(tmp_path / "oe.toml", tmp_path / "oe", progress=False, history=False)
    assert oe.result.fit.chi2_after / oe.result.dof > 3.0


def test_select_points_carries_the_condition_sigma():
    from calib.measurements import Measurements
    cond = OperatingConditions([5.0, 10.0, 12.0], [9.0, 12.0, 12.1], [0.0, 2.0, 4.0])
    m = Measurements(cond, ("power",), [[1.0], [2.0], [3.0]], [[0.1], [0.2], [0.3]],
                     condition_sigma={"pitch": [0.1, 0.2, 0.3]})
    sub = m.select_points(np.array([True, False, True]))
    np.testing.assert_array_equal(sub.condition_sigma["pitch"], [0.1, 0.3])
    np.testing.assert_array_equal(sub.values[:, 0], [1.0, 3.0])
    np.testing.assert_array_equal(sub.conditions.wind_speed, [5.0, 12.0])


def test_truncated_estimator_takes_the_marginal_problem(globals_model):
    """The truncated ML estimator on the marginal problem: its χ² is that of the stated noise (the
    conditions' scatter carried by the effective covariance), the output-error fit's is not."""
    model, truth = globals_model
    meas, _ = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=60), seed=11)
    chi2 = {}
    for mode in ("marginal", "ignore"):
        res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", errors_in_variables=mode,
                                                          **FAST)).run()
        assert res.estimate.status == "converged"
        chi2[mode] = res.fit.chi2_after / res.dof
    assert chi2["marginal"] < 1.6 < 3.0 < chi2["ignore"]


def test_condition_sigma_survives_a_written_table(tmp_path):
    from calib.measurements import Measurements
    cond = OperatingConditions([5.0, 10.0], [9.0, 12.0], [0.0, 2.0])
    m = Measurements(cond, ("power",), [[1.0e6], [2.0e6]], [[1e4], [2e4]],
                     condition_sigma={"wind_speed": [0.15, 0.3], "pitch": [0.2, 0.2]})
    back = read_measurements(m.write_csv(tmp_path / "t.csv"))
    for name in ("wind_speed", "pitch"):
        np.testing.assert_allclose(back.condition_sigma[name], m.condition_sigma[name], rtol=1e-12)


def test_the_diagnosis_refuses_condition_sigma_naming_the_key(globals_model):
    from calib.corrections import CorrectionGrid
    from calib.diagnosis.core import diagnose
    _, truth = globals_model
    meas, _ = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=12), seed=2)
    grid = CorrectionGrid([0.0, 8.0], [0.5, 1.0])
    with pytest.raises(InputError, match="diagnose with errors_in_variables") as exc:
        diagnose(load_rotor("nrel5mw"), meas, grid, BemSettings(use_tilt=False),
                 CalibrationSettings(noise="known", condition_sigma={"pitch": 0.2}, **FAST))
    assert exc.value.field == "errors_in_variables"


def test_air_density_sigma_column_is_read_and_checked(tmp_path):
    """``air_density_sigma`` read (kg/m3) into the conditions' σ; a negative one
    refused naming file, line and column; ``condition_sigma.air_density`` a valid setting."""
    m = read_measurements(write(tmp_path, "wind_speed,rotor_speed,pitch,air_density,power,air_density_sigma [kg/m3]\n"
                                          "8,10,0,1.2,1.5e6,0.004\n9,11,0,1.21,2e6,0\n"))
    np.testing.assert_allclose(m.condition_sigma["air_density"], [0.004, 0.0])
    su = condition_sigma(m, CalibrationSettings())
    assert su.shape == (2, 4) and su[0, 3] == pytest.approx(0.004) and np.all(su[:, :3] == 0.0)
    with pytest.raises(InputError) as exc:
        read_measurements(write(tmp_path, "wind_speed,rotor_speed,pitch,air_density,power,air_density_sigma\n"
                                          "8,10,0,1.2,1.5e6,0.004\n9,11,0,1.21,2e6,-0.004\n", "bad.csv"))
    assert exc.value.line == 3 and exc.value.field == "air_density_sigma" and "column 6" in exc.value.message
    CalibrationSettings(condition_sigma={"air_density": 0.004}).validate()


def test_density_sigma_share_is_the_loads_proportion_to_density(globals_model):
    """The BEM's loads are proportional to ρ (its induction does not depend on ρ), so a density σ alone
    gives every load the σ y σ_ρ/ρ exactly (closed form) in the effective covariance's share J_u Σ_u J_uᵀ,
    the channels of a point fully correlated."""
    model, _ = globals_model
    p = nominal_vector(model.parameters)
    cond = OperatingConditions([7.0, 13.0], [9.0, 12.1], [0.0, 6.0], [1.15, 1.3])
    idx = list(range(len(CHANNELS)))
    sigma_u = np.array([[0.0, 0.0, 0.0, 0.004], [0.0, 0.0, 0.0, 0.006]])
    J, n_failed = condition_sensitivities(model, p, cond, idx, sigma_u)
    y = model.evaluate(p, cond).values[:, idx]
    assert n_failed == 0 and np.all(J[:, :, :3] == 0.0)
    expected = np.abs(y) * (sigma_u[:, 3] / cond.air_density)[:, None]
    np.testing.assert_allclose(np.abs(J[:, :, 3]) * sigma_u[:, 3:], expected, rtol=1e-6)


def test_joint_and_marginal_carry_a_density_sigma(globals_model):
    """A campaign whose recorded densities scatter about the true ones (σ_ρ 1 %, stated in
    ``condition_sigma.air_density``): both estimators converge, and the stated σ widens the joint
    estimate's intervals of the global biases against the joint fit that takes the densities as exact."""
    model, truth = globals_model
    meas, true = synthesize_campaign(truth, np.zeros(0), CampaignSpec(n_records=40), seed=31)
    rng = np.random.default_rng(5)
    err = 0.01 * true.air_density * rng.standard_normal(len(true))
    noisy = dataclasses.replace(meas, conditions=dataclasses.replace(meas.conditions, air_density=true.air_density + err))
    sig = {"air_density": 0.0123}
    fits = {}
    for mode in ("marginal", "joint"):
        cal = Calibrator(model, noisy, CalibrationSettings(errors_in_variables=mode, condition_sigma=sig, **FAST))
        fits[mode] = cal.run()
        assert str(fits[mode].estimate.status) == "converged"
    exact = Calibrator(model, noisy, CalibrationSettings(errors_in_variables="joint", **FAST)).run()
    assert np.all(fits["joint"].uncertainty.std_p > exact.uncertainty.std_p)
