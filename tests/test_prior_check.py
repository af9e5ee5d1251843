"""The prior check: the data's type-II maximum-likelihood estimate of the field's prior amplitude.

Seeds 7600+ are used nowhere else in the suite.
"""

import numpy as np
import pytest
from scipy import stats
from test_uncertainty import bem_twin  # noqa: F401 (the module's BEM twin fixture)

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.result_files import load_result
from calib.checks.prior_check import PriorCheck, prior_amplitude
from calib.measurements import synthesize
from calib.report.result_sentences import sentences
from calib.types import nominal_vector


def _linear_problem(rng, n=80, m=30, k=2):
    """Sensitivities to a smooth 1-D field of m values and to k other parameters, and priors."""
    x = np.linspace(0.0, 1.0, m)
    K = 0.25 * np.exp(-0.5 * (x[:, None] - x[None]) ** 2 / 0.1 ** 2)
    Z = 2.0 * rng.standard_normal((n, m))
    Zn = rng.standard_normal((n, k))
    Kn = np.diag(np.arange(1.0, k + 1.0) ** 2)
    return Z, K, Zn, Kn


def _draw(rng, tau, Z, K, Zn, Kn):
    f = tau * np.linalg.cholesky(K + 1e-10 * np.eye(K.shape[0])) @ rng.standard_normal(K.shape[0])
    other = np.sqrt(np.diag(Kn)) * rng.standard_normal(Kn.shape[0])
    return Z @ f + Zn @ other + rng.standard_normal(Z.shape[0])


def _dense_minus2l(tau, z, Z, K, Zn, Kn):
    """−2 log-likelihood from the dense covariance (Cholesky), without the constant."""
    C = np.eye(z.size) + Zn @ Kn @ Zn.T + tau ** 2 * Z @ K @ Z.T
    L = np.linalg.cholesky(C)
    w = np.linalg.solve(L, z)
    return 2.0 * np.sum(np.log(np.diag(L))) + w @ w


def test_amplitude_and_interval_against_the_dense_likelihood():
    """τ̂ maximizes the dense marginal likelihood, and at both ends of the interval the
    likelihood ratio is χ²₁(0.95), for a problem with other parameters beside the field."""
    rng = np.random.default_rng(7601)
    Z, K, Zn, Kn = _linear_problem(rng)
    z = _draw(rng, 1.3, Z, K, Zn, Kn)
    pc = prior_amplitude(z, Z, K, Zn, Kn)
    taus = pc.amplitude * np.array([0.97, 1.0, 1.03])
    dense = [_dense_minus2l(t, z, Z, K, Zn, Kn) for t in taus]
    assert dense[1] < dense[0] and dense[1] < dense[2], dense
    crit = stats.chi2.ppf(0.95, 1)
    for end in (pc.lower, pc.upper):
        assert 0 < end < np.inf
        np.testing.assert_allclose(_dense_minus2l(end, z, Z, K, Zn, Kn) - dense[1], crit, atol=2e-3)
    np.testing.assert_allclose(pc.log_lr_at_stated, _dense_minus2l(1.0, z, Z, K, Zn, Kn) - dense[1], atol=2e-3)


@pytest.mark.parametrize("tau", [0.5, 1.0, 2.0])
def test_interval_covers_the_true_amplitude_at_its_confidence(tau):
    """Over 300 draws from the model the check assumes, the 95 % interval contains the amplitude
    of the draws at 95 % (binomial 99.7 % band for 300 draws: 91.2–98.8 %)."""
    rng = np.random.default_rng(7602 + int(10 * tau))
    Z, K, Zn, Kn = _linear_problem(rng)
    hits = 0
    for _ in range(300):
        pc = prior_amplitude(_draw(rng, tau, Z, K, Zn, Kn), Z, K, Zn, Kn)
        hits += pc.lower <= tau <= pc.upper
    assert 0.912 <= hits / 300 <= 0.988, hits


def test_verdicts_and_sentences_follow_the_numbers():
    rng = np.random.default_rng(7610)
    Z, K, Zn, Kn = _linear_problem(rng)
    large = prior_amplitude(_draw(rng, 4.0, Z, K, Zn, Kn), Z, K, Zn, Kn)
    assert large.verdict == "larger" and large.lower > 1.0
    assert f"{large.amplitude:.2g}" in large.sentence() and "too narrow" in large.sentence()
    none = prior_amplitude(_draw(rng, 0.0, Z, K, Zn, Kn), Z, K, Zn, Kn)
    assert none.verdict == "smaller" and none.upper < 1.0 and none.lower == 0.0
    assert "wider than the data need" in none.sentence()
    # data that do not see the field: the interval is unbounded above, and 1 is inside it
    blind = prior_amplitude(rng.standard_normal(80), np.zeros((80, 30)), K, Zn, Kn)
    assert blind.verdict == "consistent" and blind.upper == np.inf and blind.lower == 0.0
    assert "∞" in blind.sentence()
    assert PriorCheck(**large.to_dict()) == large


def test_calibration_reports_the_prior_check_on_the_fine_grid_and_it_survives_saving(bem_twin, tmp_path):
    """The BEM twin (refinable): the check uses the fine grid of the aliasing term, is in the
    report's sentences and survives saving; with representation_error = false it falls back to
    the calibration nodes and says so; a correction field three times the stated prior is
    called larger."""
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    rng = np.random.default_rng(7611)
    p[:grid.n_lift] = 0.1 * rng.standard_normal(grid.n_lift)       # one prior σ (0.1) per node
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7612)
    res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003, curvature_samples=0)).run()
    pc = res.uncertainty.prior_check
    assert pc["between_nodes"] is True and pc["lower"] <= pc["amplitude"] <= pc["upper"]
    assert PriorCheck(**pc).sentence() in sentences(res)
    assert f"prior check: field amplitude {pc['amplitude']:.2g} x stated" in res.summary()
    res.save(tmp_path)
    assert load_result(tmp_path).uncertainty.prior_check == pc

    coarse = Calibrator(model, meas, CalibrationSettings(cd_min=0.003, curvature_samples=0,
                                                         representation_error=False)).run()
    assert coarse.uncertainty.prior_check["between_nodes"] is False
    assert "on the calibration nodes only" in PriorCheck(**coarse.uncertainty.prior_check).sentence()

    p_big = nominal_vector(model.parameters)
    p_big[:grid.n_lift] = 0.3 * rng.standard_normal(grid.n_lift)
    meas = synthesize(model, p_big, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7613)
    big = Calibrator(model, meas, CalibrationSettings(cd_min=0.003, curvature_samples=0)).run()
    assert big.uncertainty.prior_check["verdict"] == "larger", big.uncertainty.prior_check


def test_map_point_against_the_closed_form_and_a_general_minimizer():
    """Linear model: the MAP is P Mᵀ(M P Mᵀ + I)⁻¹ z. A model with a quadratic term: the
    Gauss–Newton point minimizes ½|r|² + ½xᵀP⁻¹x as a general minimizer finds it."""
    from scipy import optimize

    from calib.checks.prior_check import map_point

    rng = np.random.default_rng(7620)
    n, m = 40, 6
    M = rng.standard_normal((n, m))
    x_true = rng.standard_normal(m)
    x = np.linspace(0.0, 1.0, m)
    P = np.exp(-0.5 * (x[:, None] - x[None]) ** 2 / 0.3 ** 2) + 0.05 * np.eye(m)
    z = M @ x_true + 0.3 * rng.standard_normal(n)

    def linear(x):
        return x, z - M @ x, np.ones(n, bool), M

    mp = map_point(linear, np.zeros(m), P)
    np.testing.assert_allclose(mp.x, P @ M.T @ np.linalg.solve(M @ P @ M.T + np.eye(n), z), atol=1e-8)
    assert mp.converged

    c = 0.3 * rng.standard_normal((n, m))
    zq = M @ x_true + c @ x_true ** 2 + 0.3 * rng.standard_normal(n)

    def quadratic(x):
        return x, zq - M @ x - c @ x ** 2, np.ones(n, bool), M + 2.0 * c * x[None, :]

    mp = map_point(quadratic, np.zeros(m), P, max_iterations=50, rtol=1e-12)
    Pinv = np.linalg.inv(P)
    ref = optimize.minimize(lambda x: 0.5 * np.sum((zq - M @ x - c @ x ** 2) ** 2) + 0.5 * x @ Pinv @ x,
                            np.zeros(m), method="BFGS", options={"gtol": 1e-10})
    np.testing.assert_allclose(mp.x, ref.x, atol=1e-5)


def test_prior_check_off_is_said_and_a_non_boolean_is_refused(bem_twin):
    from calib.errors import InputError

    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = 0.05
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7614)
    res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003, curvature_samples=0, prior_check=False)).run()
    assert res.uncertainty.prior_check == {}
    assert any(t.startswith("Prior check: not run (prior_check = false)") for t in sentences(res))
    with pytest.raises(InputError, match="prior_check"):
        CalibrationSettings(prior_check="yes").validate()


def test_a_prior_check_that_cannot_be_computed_keeps_the_result(bem_twin, monkeypatch):
    """A linear-algebra failure inside the check is recorded and said; the calibration's result stands."""
    import calib.checks.prior_check as pc_module

    def broken(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(pc_module, "prior_amplitude", broken)
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = 0.05
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7615)
    res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003, curvature_samples=0)).run()
    assert res.estimate.status == "converged" and res.n_retained > 0
    assert res.uncertainty.prior_check == {"failed": "LinAlgError: SVD did not converge"}
    assert any(t.startswith("Prior check: could not be computed (LinAlgError") for t in sentences(res))
    assert "prior check: failed (LinAlgError: SVD did not converge)" in res.summary()
