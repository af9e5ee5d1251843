"""The truncated estimator's covariance by named parts (calib.calibration.uncertainty): the parts add up in the
documented order, terms left out are zero, and a fold-dominated direction ends with at least its prior σ."""

import numpy as np

from calib.calibration.identifiability import frozen_aware_covariance
from calib.calibration.uncertainty import truncated_covariance


def _svd(seed=0, n=6, k=3):
    rng = np.random.default_rng(seed)
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    sigma_theta = np.sort(rng.uniform(0.1, 5.0, n))
    retained = np.arange(n) < k
    A = rng.standard_normal((n, n))
    return V, sigma_theta, retained, A @ A.T / n + np.eye(n)


def test_without_model_terms_the_covariance_is_the_frozen_aware_one():
    V, s, r, P = _svd()
    parts, sigmas = truncated_covariance(V, s, r, P, None, 1.0, None)
    noise, frozen = frozen_aware_covariance(V, s, r, P)
    assert np.array_equal(parts.total, noise + frozen) and sigmas == {}
    assert not parts.aliasing.any() and not parts.curvature.any() and not parts.fold.any()


def test_parts_add_in_the_documented_order():
    V, s, r, P = _svd(1)
    k = int(r.sum())
    rng = np.random.default_rng(2)
    B = rng.standard_normal((k, k))
    alias, curv = B @ B.T, np.diag(rng.uniform(0.1, 1.0, k))
    parts, _ = truncated_covariance(V, s, r, P, alias, 2.5, curv)
    Vr = V[:, r]
    expected = (parts.noise + Vr @ alias @ Vr.T) * 2.5 + Vr @ curv @ Vr.T + parts.frozen
    np.testing.assert_allclose(parts.total, expected, rtol=1e-14, atol=1e-14)
    # the fit scale multiplies noise and aliasing, not the curvature or the frozen prior
    unscaled, _ = truncated_covariance(V, s, r, P, alias, 1.0, curv)
    np.testing.assert_allclose(parts.retained - unscaled.retained, 1.5 * (parts.noise + parts.aliasing),
                               rtol=1e-12, atol=1e-12)


def test_a_fold_dominated_direction_gets_at_least_its_prior_sigma():
    V, s, r, P = _svd(3)
    parts, sigmas = truncated_covariance(V, s, r, P, None, 1.0, None, fold_thetas=[2, 2])
    v = V[:, r][:, 1]
    prior_sigma = float(np.sqrt(v @ P @ v))
    assert set(sigmas) == {2}
    assert sigmas[2]["sigma_after"] >= prior_sigma
    assert sigmas[2]["sigma_after"] > sigmas[2]["sigma_before"]
    np.testing.assert_allclose(float(np.sqrt(v @ parts.retained @ v)), sigmas[2]["sigma_after"], rtol=1e-12)
