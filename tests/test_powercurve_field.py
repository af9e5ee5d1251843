"""calib.powercurve.field: the nodal covariance split by prior-dominated and data-determined directions and
its value at another prior amplitude, against direct matrix algebra (issue 41 item 1)."""

import numpy as np
import pytest

from calib.powercurve.field import split_covariance, split_variance, variance_at_amplitude


def _problem(seed=0, n_field=8, n_other=2, rank=4):
    """A Laplace covariance (H + P⁻¹)⁻¹ with a rank-deficient H (data on ``rank`` directions only) and a
    block-diagonal prior: a correlated field block (squared-exponential) and independent other parameters."""
    rng = np.random.default_rng(seed)
    n = n_field + n_other
    x = np.arange(n_field)
    C = np.eye(n)
    C[:n_field, :n_field] = np.exp(-0.5 * (x[:, None] - x[None, :]) ** 2 / 1.5 ** 2) + 1e-9 * np.eye(n_field)
    sd = rng.uniform(0.5, 2.0, n)
    P = sd[:, None] * C * sd[None, :]
    J = rng.standard_normal((rank, n)) * 3.0
    H = J.T @ J
    mask = np.zeros(n, bool)
    mask[:n_field] = True
    return H, P, C, sd, mask, np.linalg.inv(H + np.linalg.inv(P))


def test_the_split_adds_up_and_reproduces_the_covariance_at_the_stated_amplitude():
    H, P, C, sd, mask, cov = _problem()
    s = split_covariance(cov, sd, C, mask, tau=0.6)
    for k in range(5):
        g = np.random.default_rng(10 + k).standard_normal(cov.shape[0])
        parts = split_variance(s, g)
        assert parts["data"] + parts["prior"] == pytest.approx(g @ cov @ g, rel=1e-8)
        assert variance_at_amplitude(s, g, 1.0) == pytest.approx(g @ cov @ g, rel=1e-8)


@pytest.mark.parametrize("tau", [0.3, 0.8, 2.5])
def test_another_amplitude_equals_the_posterior_under_the_rescaled_prior(tau):
    H, P, C, sd, mask, cov = _problem(seed=1)
    T = np.diag(np.where(mask, tau, 1.0))
    direct = np.linalg.inv(H + np.linalg.inv(T @ P @ T))      # the Laplace covariance under τ² on the field
    s = split_covariance(cov, sd, C, mask, tau=tau)
    for k in range(5):
        g = np.random.default_rng(20 + k).standard_normal(cov.shape[0])
        assert variance_at_amplitude(s, g, tau) == pytest.approx(g @ direct @ g, rel=1e-6)


def test_a_direction_the_data_do_not_see_is_prior_dominated_and_one_they_pin_is_not():
    H, P, C, sd, mask, cov = _problem(seed=2, rank=3)
    s = split_covariance(cov, sd, C, mask)
    # a functional the data carry no information on: g P Hᵀ = 0, i.e. g P^½ in the null space of Ĥ
    w, V = np.linalg.eigh(H)
    Ph = sd[:, None] * np.real(np.linalg.cholesky(C))
    Hh = Ph.T @ H @ Ph
    wh, Vh = np.linalg.eigh(Hh)
    null_dir, pinned_dir = Vh[:, 0], Vh[:, -1]
    g_null = np.linalg.solve(Ph.T, null_dir)        # g P^½ = null_dir
    g_pin = np.linalg.solve(Ph.T, pinned_dir)
    a = split_variance(s, g_null)
    assert a["data"] < 1e-8 * a["prior"] and a["prior"] == pytest.approx(g_null @ P @ g_null, rel=1e-6)
    b = split_variance(s, g_pin)
    assert wh[-1] > 10 and b["prior"] < 1e-8 * b["data"]
