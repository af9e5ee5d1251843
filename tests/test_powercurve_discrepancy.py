"""The model discrepancy across the power-curve bins (issue 41): its second moments against a Monte Carlo of
the Gaussian process's conditional draws, its diagonal against the prediction's per-point σ; and what the
report says where the delta method and the draws disagree."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from calib.calibration.discrepancy import ChannelDiscrepancy
from calib.cli import main
from calib.powercurve import FixedSpeed, calibrated_power_curve, iec_bins
from calib.powercurve.discrepancy import discrepancy_correlation, discrepancy_covariance

ROOT = Path(__file__).resolve().parents[1]


def _process(seed=3, n=30, tau=0.03, length=0.3, noise=0.01):
    """A discrepancy process fitted to residuals drawn from it (the definition of the module notes of
    calib.calibration.discrepancy: weights (τ²K + S)⁻¹ e, inverse (τ²K + S)⁻¹)."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 1.0, (n, 3))
    K = np.exp(-0.5 * ((x[:, None] - x[None]) ** 2).sum(-1) / length ** 2)
    S = np.full(n, noise ** 2)
    A = tau ** 2 * K + np.diag(S)
    e = np.linalg.cholesky(A) @ rng.standard_normal(n) + 0.02      # a misfit with a common part
    inv = np.linalg.inv(A)
    return ChannelDiscrepancy("power", tau, length, 1e-4, x, inv @ e, inv), e, S


def test_aep_discrepancy_variance_matches_a_monte_carlo_of_correlated_draws():
    """cᵀDc, D = ŷŷᵀ∘(μμᵀ + Σ), against the mean square of c·(ŷ∘δ) over 100 000 draws of δ from the process
    conditioned on the residuals (Matheron's rule: a joint prior draw corrected by the residuals, not the
    closed form); its diagonal against the per-point mean square of calib.calibration.discrepancy."""
    proc, e, S = _process()
    n_new = 25
    x_new = np.column_stack([np.linspace(0.1, 0.9, n_new), np.full(n_new, 0.3), np.linspace(0.2, 0.8, n_new)])
    y = 1e6 * (0.2 + np.linspace(0.0, 1.0, n_new) ** 3)                       # W
    c = np.random.default_rng(1).uniform(0.5, 1.5, n_new) * 1e-3               # MWh per W
    D = discrepancy_covariance(proc, x_new, y)
    np.testing.assert_allclose(np.diag(D), proc.mean_square(x_new) * y ** 2, rtol=1e-9)

    rng = np.random.default_rng(2)
    x_all = np.vstack([proc.x, x_new])
    Kj = proc.amplitude ** 2 * np.exp(-0.5 * ((x_all[:, None] - x_all[None]) ** 2).sum(-1) / proc.length ** 2)
    w, V = np.linalg.eigh(Kj)
    L = V * np.sqrt(np.clip(w, 0.0, None))
    m = 100_000
    f = rng.standard_normal((m, x_all.shape[0])) @ L.T
    eps = rng.standard_normal((m, proc.x.shape[0])) * np.sqrt(S)
    n = proc.x.shape[0]
    K_nc = Kj[n:, :n]
    A = Kj[:n, :n] + np.diag(S)
    delta = f[:, n:] + np.linalg.solve(A, (e[None, :] - f[:, :n] - eps).T).T @ K_nc.T
    aep_err = delta @ (c * y)
    mc = float(np.mean(aep_err ** 2))
    assert float(c @ D @ c) == pytest.approx(mc, rel=0.02)
    # correlated, not perfectly: strictly below the per-bin σ added linearly (here, with a common misfit,
    # above them in quadrature)
    sd = np.sqrt(np.diag(D))
    assert float(np.sum(c * sd ** 2 * c)) < float(c @ D @ c) < 0.999 * float(c @ sd) ** 2
    R = discrepancy_correlation(proc, x_new)
    np.testing.assert_allclose(sd[:, None] * R * sd[None, :], D, rtol=1e-9, atol=1e-12 * D.max())


@pytest.fixture(scope="module")
def wind_tunnel_result(tmp_path_factory):
    """A real calibration: workflows/wind_tunnel_hub_loads.toml (Phase VI, MAP, power and thrust)."""
    from calib.calibration.result_files import load_result

    out = tmp_path_factory.mktemp("wt")
    assert main(["run", str(ROOT / "workflows" / "wind_tunnel_hub_loads.toml"), "--out", str(out), "-q"]) == 0
    return load_result(next(out.glob("stage*/result.json")).parent)


@pytest.fixture(scope="module")
def misfit_result(wind_tunnel_result):
    """The calibration with its power data given a smooth 4 % misfit in wind speed, so the χ² test fires
    and a discrepancy process is fitted."""
    result = wind_tunnel_result
    fit = result.fit
    i = list(result.channels).index("power")
    v = np.asarray(result.conditions["wind_speed"], float)
    measured = fit.measured.copy()
    measured[:, i] = fit.model_after[:, i] * (1.0 + 0.04 * np.sin(v / 3.0))
    return result.replace(fit=dataclasses.replace(fit, measured=measured))


def test_the_power_curve_carries_the_discrepancy_across_the_bins(misfit_result):
    """The power curve's discrepancy second moments have the prediction's per-bin σ² on their diagonal
    (predict_outputs, another code path), and the AEP's discrepancy σ is positive and no larger than the
    per-bin σ added linearly (Cauchy-Schwarz; it can fall below them in quadrature: the misfit's
    conditional mean changes sign over the bins and cancels in the sum)."""
    from calib.calibration.discrepancy import fit_discrepancy
    from calib.powercurve.aep import aep_weights
    from calib.powercurve.command import distributions

    assert "power" in fit_discrepancy(misfit_result).processes
    pc = calibrated_power_curve(misfit_result, iec_bins(5.0, 15.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=0)
    assert pc.discrepancy_cov is not None and np.all(pc.discrepancy_std > 0)
    np.testing.assert_allclose(np.sqrt(np.diag(pc.discrepancy_cov)), pc.discrepancy_std, rtol=1e-8)
    assert any("covariance across the bins" in n and "discrepancy" in n for n in pc.notes)
    for row in pc.aep_table(distributions()):
        c = aep_weights(pc.wind_speed, distributions()[row["distribution"]]) * pc.generator_efficiency / 1e6
        s = row["sigma_mwh"]["model discrepancy"]
        assert 0 < s <= float(c @ pc.discrepancy_std) * (1 + 1e-9)


def _variable(result, factor):
    from calib.powercurve import VariableSpeed
    from calib.rotor.geometry import OperatingSchedule

    u = result.uncertainty
    scaled = result.replace(uncertainty=dataclasses.replace(u, cov_p=u.cov_p * factor, cov_alias=u.cov_alias * factor))
    model = scaled.rebuild_model()
    sched = OperatingSchedule(rated_power=5000.0, min_rotor_speed=40.0, max_rotor_speed=72.0, design_tsr=5.0,
                              fine_pitch=3.0, cut_in=4.0, cut_out=20.0)
    return scaled, model, VariableSpeed.from_rotor(dataclasses.replace(model.rotor, schedule=sched))


def test_the_report_says_where_and_why_the_delta_method_leaves_the_draws(wind_tunnel_result):
    """A covariance 100× the posterior's puts the draws where the power is curved in the parameters: the
    draws' mean AEP leaves the central curve's (a linear map would keep it), and the report names that
    and the bins where some draws are capped at rated power (checked on the draws' power, not their
    pitch); at 10⁻⁴× the covariance the two agree and the report says so."""
    from calib.powercurve.command import distributions, summary_paragraph
    from calib.powercurve.statements import capped_bins, delta_statement

    v = iec_bins(5.0, 15.0, 1.0)
    result, model, schedule = _variable(wind_tunnel_result, 100.0)
    pc = calibrated_power_curve(result, v, schedule, n_draws=200, seed=4, model=model)
    row = next(r for r in pc.aep_table(distributions()) if r["distribution"] == "Rayleigh 8 m/s")
    n = row["draws_used"]
    shift = row["draws_mean_aep_mwh"] - row["p50_mwh"]
    assert abs(row["sigma_calibration_delta_mwh"] / row["sigma_mwh"]["calibration (draws)"] - 1) > 0.1
    said = delta_statement(pc, row)
    assert "more than" in said and "% off" in said
    assert ("curved in the parameters" in said) == (abs(shift) > 3 * row["sigma_mwh"]["calibration (draws)"] / np.sqrt(n))
    # region 3 is where a draw's pitch solve ran (pitch off the fine pitch), told apart by the solve, not by a
    # power threshold (region-2 draws can sit within the pitch solve's tolerance below rated power)
    P, pitch, ok = pc.draws["power"], pc.draws["pitch"], pc.draw_status == 0
    pitched = ok & (pitch != schedule.fine_pitch)
    unpitched = ok & (pitch == schedule.fine_pitch)
    assert np.all(pitched | unpitched | ~ok)
    # the pitch solve's own convergence: rated power to its tolerance; region 2 never above rated
    assert np.all(np.abs(P[pitched] / schedule.rated_power - 1) <= schedule.pitch_tol_power * (1 + 1e-9))
    assert np.all(P[unpitched] <= schedule.rated_power)
    np.testing.assert_array_equal(capped_bins(pc), np.any(pitched, axis=0) & np.any(unpitched, axis=0))
    assert capped_bins(pc).any() and "rated-power capping" in said
    assert said in summary_paragraph(pc, pc.aep_table(distributions()))

    small, model, schedule = _variable(wind_tunnel_result, 1e-4)
    pc = calibrated_power_curve(small, v, schedule, n_draws=200, seed=4, model=model)
    row = next(r for r in pc.aep_table(distributions()) if r["distribution"] == "Rayleigh 8 m/s")
    assert delta_statement(pc, row).endswith("within 10 %.")


def test_beside_a_discrepancy_the_power_curve_and_predict_use_the_covariance_at_k_prime(misfit_result):
    """Where the power channel carries a discrepancy process, the power curve draws and linearizes from the
    Laplace covariance re-formed at k' (calib.calibration.discrepancy_scale), its sandwich uses k' too, and
    the prediction and the report's notes say so; k' ≤ the recorded k."""
    from calib.calibration.discrepancy import fit_discrepancy
    from calib.calibration.discrepancy_scale import discrepancy_aware_covariance
    from calib.powercurve.sampling import sampling_covariance
    from calib.types import OperatingConditions

    est = discrepancy_aware_covariance(misfit_result, fit_discrepancy(misfit_result))
    k = float(misfit_result.uncertainty.fit_scale)
    assert est.reformed and 1.0 <= est.fit_scale <= k and est.recorded_fit_scale == k
    pc = calibrated_power_curve(misfit_result, iec_bins(5.0, 15.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=0)
    assert pc.fit_scale == pytest.approx(est.fit_scale, rel=1e-12)
    assert any("k' =" in n for n in pc.notes)
    np.testing.assert_allclose(pc.sampling_cov, sampling_covariance(misfit_result) * est.fit_scale / k, rtol=1e-12)
    cond = OperatingConditions(np.array([7.0, 10.0]), np.array([72.0, 72.0]), np.array([3.0, 3.0]), 1.225)
    pred = misfit_result.predict(cond, misfit_result.rebuild_model())
    assert "re-formed" in pred.discrepancy
