"""Model discrepancy in predictions (issue 37, item 1; calib.calibration.discrepancy): a channel
that fits within its noise gets no term; one that misfits gets a Gaussian process whose mean
square is about the misfit near the calibration points and its full amplitude far from them.
Checked against the closed form of a one-point process and on residuals built to a known form."""

from types import SimpleNamespace

import numpy as np
import pytest

from calib.calibration.discrepancy import LENGTHS, ChannelDiscrepancy, _kernel, fit_discrepancy

RADIUS = 63.0


def _result(measured, model, sigma, tsr, pitch=None, rpm=10.0):
    """The parts of a CalibrationResult that fit_discrepancy reads."""
    tsr = np.asarray(tsr, float)
    v = rpm * np.pi / 30 * RADIUS / tsr
    n = tsr.size
    fit = SimpleNamespace(measured=measured, model_after=model, sigma=sigma, status_after=np.zeros(n, int))
    cond = {"wind_speed": v, "rotor_speed": np.full(n, rpm), "pitch": np.zeros(n) if pitch is None else pitch}
    return SimpleNamespace(fit=fit, conditions=cond, channels=("power",),
                           provenance=SimpleNamespace(rotor_radius=RADIUS))


def test_the_conditional_mean_square_of_a_one_point_process_is_the_closed_form():
    """One residual e with noise s²: μ = τ²k e / (τ² + s²), v = τ² − τ⁴k² / (τ² + s²)."""
    tau, s2, e, length = 0.05, 0.01 ** 2, 0.04, 0.3
    x = np.zeros((1, 3))
    inverse = np.array([[1.0 / (tau ** 2 + s2)]])
    q = ChannelDiscrepancy("power", tau, length, 1e-6, x, inverse @ [e], inverse)
    x_new = np.array([[0.0, 0.0, 0.0], [0.2, 0.0, 0.1], [5.0, 0.0, 0.0]])
    k = np.exp(-0.5 * (x_new ** 2).sum(axis=1) / length ** 2)
    mean = tau ** 2 * k * e / (tau ** 2 + s2)
    var = tau ** 2 - tau ** 4 * k ** 2 / (tau ** 2 + s2)
    np.testing.assert_allclose(q.mean_square(x_new), mean ** 2 + var, rtol=1e-12)
    assert q.mean_square(x_new)[-1] == pytest.approx(tau ** 2, rel=1e-9)   # far away: the full amplitude


def test_a_channel_within_its_noise_gets_no_term():
    """Pure noise: the χ² gate lets a process through on about 1 % of the seeds (its level), and then
    one of no more than the noise's size; otherwise the prediction's variance is untouched."""
    tsr = np.linspace(4, 10, 30)
    model = np.full((30, 1), 1e6)
    sigma = np.full((30, 1), 1e4)
    new = {"wind_speed": np.array([5.0, 30.0]), "rotor_speed": np.full(2, 10.0), "pitch": np.zeros(2)}
    fired = []
    for seed in range(3702, 3902):
        rng = np.random.default_rng(seed)
        d = fit_discrepancy(_result(model + sigma * rng.standard_normal((30, 1)), model, sigma, tsr))
        if d.processes:
            fired.append(d.processes["power"].amplitude)
        else:
            assert np.all(d.variance(new, RADIUS, np.full((2, 1), 1e6)) == 0)
            assert "no model-discrepancy term" in d.words()
    assert len(fired) <= 6, len(fired)                       # 200 seeds at a 1 % level: 2 expected
    assert all(tau < 0.01 for tau in fired), fired            # below the 1 % noise


def test_a_systematic_misfit_widens_predictions_most_far_from_the_calibration():
    """A 4 % misfit growing with λ on 1 % noise: the process is fitted; at the calibration points its
    root mean square is about the misfit there; beyond the calibrated λ it reaches its amplitude,
    at least the largest misfit seen."""
    rng = np.random.default_rng(3701)
    tsr = np.linspace(4, 8, 25)
    form = 0.04 * (tsr - 4) / 4                              # 0 at λ 4, 4 % at λ 8
    model = np.full((25, 1), 1e6)
    sigma = 0.01 * model
    measured = model * (1 + form[:, None]) + sigma * rng.standard_normal((25, 1))
    d = fit_discrepancy(_result(measured, model, sigma, tsr))
    q = d.processes["power"]
    assert q.p_value < 1e-6 and q.length in LENGTHS
    cond = lambda lam: {"wind_speed": 10 * np.pi / 30 * RADIUS / np.asarray(lam, float),  # noqa: E731
                        "rotor_speed": np.full(len(lam), 10.0), "pitch": np.zeros(len(lam))}
    inside = np.sqrt(d.variance(cond(tsr), RADIUS, model))[:, 0] / 1e6
    assert np.sqrt(np.mean(inside ** 2)) == pytest.approx(np.sqrt(np.mean(form ** 2)), rel=0.35)
    beyond = np.sqrt(d.variance(cond([12.0]), RADIUS, np.full((1, 1), 1e6)))[0, 0] / 1e6
    assert beyond >= 0.8 * form.max()                         # past the calibrated λ: at least the misfit seen
    far = np.sqrt(d.variance(cond([200.0]), RADIUS, np.full((1, 1), 1e6)))[0, 0] / 1e6
    assert far == pytest.approx(q.amplitude, rel=1e-6)       # far away: the process's amplitude


def test_the_kernel_is_one_on_the_diagonal_and_falls_with_distance():
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    k = _kernel(x, x, 0.5)
    assert np.allclose(np.diag(k), 1.0) and k[0, 1] == pytest.approx(np.exp(-2.0))


def test_a_large_calibration_fits_its_process_on_an_evenly_spaced_subset():
    """2 000 points: the process is fitted on MAX_POINTS of them (a few seconds, not minutes), and
    still finds the misfit's size."""
    from calib.calibration.discrepancy import MAX_POINTS

    rng = np.random.default_rng(3703)
    tsr = np.linspace(4, 8, 2000)
    model = np.full((2000, 1), 1e6)
    sigma = 0.01 * model
    measured = model * (1 + 0.03 * np.sin(tsr)[:, None]) + sigma * rng.standard_normal((2000, 1))
    q = fit_discrepancy(_result(measured, model, sigma, tsr)).processes["power"]
    assert q.x.shape[0] == MAX_POINTS
    assert 0.01 < q.amplitude < 0.1
