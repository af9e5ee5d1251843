"""Model discrepancy in predictions (issue 37, item 1; calib.calibration.discrepancy): a channel
that fits within its noise gets no term; one that misfits gets a Gaussian process whose mean
square is about the misfit near the calibration points and its full amplitude far from them.
Checked against the closed form of a one-point process and on residuals built to a known form."""

from types import SimpleNamespace

import numpy as np
import pytest

from calib.calibration.discrepancy import LENGTH_BOUNDS, ChannelDiscrepancy, _kernel, fit_discrepancy

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
    assert q.p_value < 1e-6 and np.all((q.length >= LENGTH_BOUNDS[0]) & (q.length <= LENGTH_BOUNDS[1]))
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


def test_the_marginal_likelihood_gradient_is_the_finite_difference_one():
    """The analytic gradient in (log τ, log ℓ_d) against central differences of the likelihood itself."""
    from calib.calibration.discrepancy import _nll_grad

    rng = np.random.default_rng(4101)
    x = rng.uniform(0, 1, (25, 3))
    d2 = np.moveaxis((x[:, None, :] - x[None, :, :]) ** 2, -1, 0)
    e, s2 = 0.02 * rng.standard_normal(25), np.full(25, 0.01 ** 2)
    theta = np.log([0.02, 0.3, 0.7, 2.0])
    _, g = _nll_grad(theta, d2, e, s2)
    h = 1e-5
    fd = [(_nll_grad(theta + h * np.eye(4)[k], d2, e, s2)[0] - _nll_grad(theta - h * np.eye(4)[k], d2, e, s2)[0])
          / (2 * h) for k in range(4)]
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-7)


def test_a_known_ard_process_is_recovered_and_its_conditional_moments_match_a_monte_carlo():
    """Monte Carlo of a known GP (issue 41): τ = 3 %, ℓ = (0.2, 3, 3) span units (only λ matters), noise 1 %,
    60 calibration points and 20 held-out ones per seed (seeds 4110-4149). (a) With the true τ and ℓ, the
    held-out discrepancy standardized by ChannelDiscrepancy's conditional mean and variance has mean square
    1 (0.85-1.15: 800 points of a χ²₁, about ±0.1 at 2σ) and 90 % of it inside ±1.645 (0.86-0.94). (b) The
    fit (ARD) recovers the hyperparameters: median τ and λ length within 30 % of the truth, and the λ length
    the shortest on most seeds. (The plug-in of the fitted τ, ℓ is known to under-state the held-out
    variance with 60 points in 3 conditions; that is not what this test checks.)"""
    from calib.calibration.discrepancy import _fit_process

    tau, ell, noise = 0.03, np.array([0.2, 3.0, 3.0]), 0.01
    z, fits = [], []
    for seed in range(4110, 4150):
        rng = np.random.default_rng(seed)
        x = rng.uniform(0, 1, (80, 3))
        delta = np.linalg.cholesky(tau ** 2 * _kernel(x, x, ell) + 1e-12 * np.eye(80)) @ rng.standard_normal(80)
        cal, new = slice(0, 60), slice(60, 80)
        e = delta[cal] + noise * rng.standard_normal(60)
        inverse = np.linalg.inv(tau ** 2 * _kernel(x[cal], x[cal], ell) + noise ** 2 * np.eye(60))
        q = ChannelDiscrepancy("power", tau, ell, 1e-6, x[cal], inverse @ e, inverse)
        k = tau ** 2 * _kernel(x[new], x[cal], ell)
        mu = k @ q.weights
        v = q.mean_square(x[new]) - mu ** 2
        z.extend((delta[new] - mu) / np.sqrt(v))
        fits.append(_fit_process(x[cal], e, np.full(60, noise ** 2)))
    z = np.array(z)
    assert 0.85 < np.mean(z ** 2) < 1.15 and 0.86 < np.mean(np.abs(z) < 1.6449) < 0.94
    t_fit = np.array([f[1] for f in fits])
    l_fit = np.array([f[2] for f in fits])
    assert np.median(t_fit) == pytest.approx(tau, rel=0.3)
    assert np.median(l_fit[:, 0]) == pytest.approx(ell[0], rel=0.3)
    assert np.sum(np.argmin(l_fit, axis=1) == 0) >= 32


def test_the_residuals_choose_their_units():
    """A misfit of constant size in watts on outputs that vary tenfold is modelled in channel units; one
    proportional to the output in relative units (the marginal likelihood in channel units decides)."""
    tsr = np.linspace(4, 10, 40)
    y = np.linspace(1e5, 1e6, 40)[:, None]
    sigma = np.full((40, 1), 5e3)
    rng = np.random.default_rng(4102)
    smooth = np.sin(tsr)[:, None]
    absolute = fit_discrepancy(_result(y + 3e4 * smooth + sigma * rng.standard_normal((40, 1)), y, sigma, tsr))
    relative = fit_discrepancy(_result(y * (1 + 0.1 * smooth) + sigma * rng.standard_normal((40, 1)), y, sigma, tsr))
    qa, qr = absolute.processes["power"], relative.processes["power"]
    assert qa.units == "channel" and qr.units == "relative"
    assert qa.amplitude * qa.reference == pytest.approx(3e4, rel=0.5)
    assert qr.amplitude == pytest.approx(0.1, rel=0.5)
    assert "channel units" in absolute.words() and "% of the output" in relative.words()
