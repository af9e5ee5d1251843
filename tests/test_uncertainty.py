"""Honest uncertainty: automatic truncation, frozen-direction covariance, confounding,
goodness of fit and predictions (issue: bands that cover the truth).

Seeds here (7000+) are used nowhere else in the suite.
"""

import dataclasses

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.identifiability import frozen_aware_covariance
from calib.calibration.result_files import load_result
from calib.calibration.truncation import cv_curve, prior_limit
from calib.cli import main as cli_main
from calib.corrections import CorrectionGrid
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector


@pytest.mark.parametrize("n_folds", [None, 4])
def test_cv_curve_equals_refitting_without_each_fold(n_folds):
    """The block leave-out identity against brute force: refit the truncated SVD without each
    fold (one point, or every 4th point) and predict it."""
    rng = np.random.default_rng(7001)
    n_pts, n_ch, n_par = 15, 3, 8
    M = rng.standard_normal((n_pts * n_ch, n_par)) * np.logspace(0, -3, n_par)
    z = M @ rng.standard_normal(n_par) + rng.standard_normal(n_pts * n_ch)
    curve = cv_curve(M, z, n_ch, n_folds=n_folds)
    U, s, Vt = np.linalg.svd(M, full_matrices=False)
    K = n_pts if n_folds is None else n_folds
    for k in (1, 3, 6):
        # the truncated fit is the least-squares fit in span(U_k), i.e. a regression on U_k
        X = U[:, :k]
        per_fold = []
        for f in range(K):
            rows = np.flatnonzero(np.repeat(np.arange(n_pts) % K == f, n_ch))
            keep = np.setdiff1d(np.arange(n_pts * n_ch), rows)
            coef = np.linalg.lstsq(X[keep], z[keep], rcond=None)[0]
            per_fold.append(np.mean((z[rows] - X[rows] @ coef) ** 2))
        np.testing.assert_allclose(curve.cv[k], np.mean(per_fold), rtol=1e-9)
    assert curve.n_retained[0] == 0 and curve.chosen == int(np.argmin(curve.cv))


def _svd_matrix(rng, s, n_rows=40):
    """A matrix with singular values ``s`` and random orthonormal singular vectors, and V."""
    n = len(s)
    U = np.linalg.qr(rng.standard_normal((n_rows, n)))[0]
    V = np.linalg.qr(rng.standard_normal((n, n)))[0]
    return U @ np.diag(s) @ V.T, V


def test_prior_limit_stops_before_the_first_direction_the_prior_knows_better():
    """Freezing v_i costs its prior variance v_iᵀPv_i, estimating it costs 1/s_i²: the limit is
    the number of leading directions where the data win, for an isotropic and a correlated P."""
    rng = np.random.default_rng(7004)
    s = np.array([10.0, 3.0, 1.2, 0.9, 0.1])
    M, V = _svd_matrix(rng, s)
    assert prior_limit(M, np.eye(5)) == 3               # 1/s² = 0.01, 0.11, 0.69 | 1.23, 100
    assert prior_limit(M, 4.0 * np.eye(5)) == 4         # prior 2 units: 1.23 <= 4 < 100
    # a prior that says the second direction is almost surely small: stop before it
    P = V @ np.diag([1.0, 0.05, 1.0, 1.0, 1.0]) @ V.T
    assert prior_limit(M, P) == 1
    # rows that take no part (failed points) are left out
    M_failed = np.vstack([M, 1e3 * rng.standard_normal((3, 5))])
    assert prior_limit(M_failed, np.eye(5), np.r_[np.ones(40, bool), np.zeros(3, bool)]) == 3


def test_the_automatic_choice_stays_within_the_prior_limit():
    """Data whose cross-validated error keeps falling into the weak directions: without a limit
    the choice goes there; with one it stops at the limit, and the curve still covers every k."""
    rng = np.random.default_rng(7005)
    n_pts, n_ch = 30, 2
    s = np.logspace(1, -2, 8)
    M, V = _svd_matrix(rng, s, n_pts * n_ch)
    z = M @ (V @ (20.0 / s)) + rng.standard_normal(n_pts * n_ch)   # large signal on every direction
    free = cv_curve(M, z, n_ch, n_folds=5)
    assert free.chosen > 3 and free.prior_limit is None
    limited = cv_curve(M, z, n_ch, n_folds=5, max_choice=3)
    assert limited.chosen <= 3 and limited.prior_limit == 3
    np.testing.assert_array_equal(limited.cv, free.cv)
    assert limited.to_dict()["prior_limit"] == 3 and "prior_limit" not in free.to_dict()


def test_a_calibration_retains_no_direction_the_prior_knows_better():
    """The recorded limit is the prior limit of the final linearization (recomputed here from
    the result's singular values and vectors and its stated prior), the choice is within it, and
    the report says so."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    from calib.report.result_sentences import sentences

    model = TwinModel(channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 9))
    meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=7122)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None)).run()
    field = model.correction_field()
    std = res.uncertainty.prior_std / res.estimate.scale
    P = np.outer(std, std) * field.node_correlation(res.provenance.settings["prior_correlation"])
    data_var = 1.0 / res.identifiability.singular_values ** 2
    prior_var = np.einsum("ji,jk,ki->i", res.identifiability.V, P, res.identifiability.V)
    expected = int(np.argmax(data_var > prior_var)) if np.any(data_var > prior_var) else data_var.size
    assert res.identifiability.truncation["prior_limit"] == expected
    assert res.n_retained <= expected
    assert any("better than the prior" in t for t in sentences(res))


def test_frozen_directions_carry_prior_variance():
    V = np.linalg.qr(np.random.default_rng(7002).standard_normal((4, 4)))[0]
    sig = np.array([0.1, 0.2, 5.0, 50.0])
    keep = np.array([True, True, False, False])
    prior = np.full(4, 1.0)
    cr, cf = frozen_aware_covariance(V, sig, keep, prior)
    np.testing.assert_allclose(cr, (V[:, :2] * sig[:2] ** 2) @ V[:, :2].T)
    np.testing.assert_allclose(cf, V[:, 2:] @ V[:, 2:].T)  # isotropic prior: projector onto the frozen space
    # nothing frozen -> no prior term; everything frozen -> the prior itself
    assert np.allclose(frozen_aware_covariance(V, sig, np.ones(4, bool), prior)[1], 0)
    np.testing.assert_allclose(frozen_aware_covariance(V, sig, np.zeros(4, bool), prior)[1], np.eye(4), atol=1e-12)


def test_frozen_directions_with_a_full_prior_covariance():
    """A full prior matrix: the frozen part is Π_N P Π_N; a diagonal one gives the 1-σ form."""
    rng = np.random.default_rng(7003)
    V = np.linalg.qr(rng.standard_normal((5, 5)))[0]
    sig = np.array([0.1, 0.3, 2.0, 9.0, 40.0])
    keep = np.array([True, True, False, False, False])
    std = np.array([1.0, 2.0, 0.5, 1.0, 3.0])
    np.testing.assert_allclose(frozen_aware_covariance(V, sig, keep, np.diag(std ** 2))[1],
                               frozen_aware_covariance(V, sig, keep, std)[1], atol=1e-12)
    L = rng.standard_normal((5, 5))
    P = L @ L.T
    Pn = V[:, ~keep] @ V[:, ~keep].T
    np.testing.assert_allclose(frozen_aware_covariance(V, sig, keep, P)[1], Pn @ P @ Pn, atol=1e-12)


def _quadratic_toy(seed: int, curvature: np.ndarray):
    """Whitened residual r(p̃) = z − M p̃ − b (v₃ᵀ p̃)² with M's third singular direction frozen."""
    rng = np.random.default_rng(seed)
    U = np.linalg.qr(rng.standard_normal((12, 3)))[0]
    V = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    s = np.array([20.0, 5.0, 0.05])
    M = (U * s) @ V.T
    z = rng.standard_normal(12)

    def residual_at(step):
        return z - M @ step - curvature * (V[:, 2] @ step) ** 2, np.ones(12, bool), step

    return M, V, 1.0 / s, z, residual_at


def test_frozen_curvature_covariance_is_the_second_moment_of_the_quadratic_bias():
    """y = M p̃ + b x² with x = v₃ᵀp̃ frozen, x ~ N(0, σ_f²): the retained θ take up
    Δθ = −S⁻² V_IDᵀ Mᵀ b x², whose second moment is 3 σ_f⁴ g gᵀ with g = S⁻² V_IDᵀ Mᵀ b."""
    from calib.calibration.frozen_curvature import frozen_curvature_covariance

    b = np.linspace(-1.0, 2.0, 12)
    M, V, sig, z, residual_at = _quadratic_toy(7020, b)
    keep = np.array([True, True, False])
    prior_std = 1.5
    P = np.eye(3) * prior_std ** 2
    cov, info = frozen_curvature_covariance(residual_at, z, np.ones(12, bool), M, V, sig, keep, P, 20000)
    g = (V[:, :2] * sig[:2] ** 2).T @ M.T @ b
    expected = 3 * prior_std ** 4 * np.outer(g, g)
    # Monte Carlo: E[x⁴] from 20 000 draws has a relative standard deviation of 2.3 %
    np.testing.assert_allclose(cov, expected, rtol=0.07)
    assert info == {"samples": 20000, "used": 20000, "samples_with_failed_points": 0}
    # a linear model has no such term: the frozen components move the outputs along U_NID only
    M, V, sig, z, residual_at = _quadratic_toy(7020, np.zeros(12))
    cov0, _ = frozen_curvature_covariance(residual_at, z, np.ones(12, bool), M, V, sig, keep, P, 50)
    assert np.abs(cov0).max() < 1e-20 * np.abs(expected).max() + 1e-24
    # nothing frozen or nothing retained: nothing to propagate
    assert frozen_curvature_covariance(residual_at, z, np.ones(12, bool), M, V, sig, np.ones(3, bool), P,
                                       50)[0].shape == (3, 3)
    assert frozen_curvature_covariance(residual_at, z, np.ones(12, bool), M, V, sig, np.zeros(3, bool), P,
                                       50)[0].shape == (0, 0)


def test_frozen_curvature_covariance_leaves_out_rows_that_did_not_converge():
    """A draw at which some points fail contributes through its converged rows only, and is counted."""
    from calib.calibration.frozen_curvature import frozen_curvature_covariance

    b = np.ones(12)
    M, V, sig, z, residual_at = _quadratic_toy(7021, b)
    keep = np.array([True, True, False])
    failed = np.zeros(12, bool)
    failed[:4] = True

    def failing(step):
        r, _, taken = residual_at(step)
        return np.where(failed, np.nan, r), ~failed, taken

    cov, info = frozen_curvature_covariance(failing, z, np.ones(12, bool), M, V, sig, keep, np.eye(3), 400)
    assert np.all(np.isfinite(cov)) and info["samples_with_failed_points"] == 400 and info["used"] == 400
    b_ok = np.where(failed, 0.0, b)
    M2, V2, sig2, z2, ra2 = _quadratic_toy(7021, b_ok)
    cov_ok, _ = frozen_curvature_covariance(ra2, z2, np.ones(12, bool), M2, V2, sig2, keep, np.eye(3), 400)
    np.testing.assert_allclose(cov, cov_ok, rtol=1e-10)


def test_the_frozen_part_of_an_in_span_truth_widens_the_retained_covariance_where_few_theta_are_kept(bem_twin):
    """On the BEM twin, a calibration that keeps few θ has a larger retained covariance with
    the curvature term than without it, by the ratio it reports; without it the report says
    the term is left out."""
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    p[:grid.n_lift] = (0.15 * np.sin(A / 5.0) * np.cos(3 * E)).ravel()     # about one prior σ, in the span
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7022)
    st = CalibrationSettings(estimator="truncated", sigma_bar=0.05, cd_min=None)
    with_term = Calibrator(model, meas, st).run()
    without = Calibrator(model, meas, dataclasses.replace(st, curvature_samples=0)).run()
    assert 0 < with_term.n_retained < with_term.n_params
    np.testing.assert_allclose(with_term.estimate.p_hat, without.estimate.p_hat)
    Vr = with_term.identifiability.V[:, with_term.identifiability.retained]
    D = np.outer(with_term.estimate.scale, with_term.estimate.scale)
    extra = np.diag(Vr.T @ ((with_term.uncertainty.cov_p - without.uncertainty.cov_p) / D) @ Vr) / with_term.identifiability.sigma_theta[with_term.identifiability.retained] ** 2
    cur = with_term.uncertainty.curvature
    assert cur["samples"] == 32 and cur["used"] >= 1
    np.testing.assert_allclose(extra.mean(), cur["variance_ratio_mean"], rtol=1e-6)
    np.testing.assert_allclose(extra.max(), cur["variance_ratio_max"], rtol=1e-6)
    assert cur["variance_ratio_max"] > 0
    from calib.report.result_sentences import sentences

    assert any("propagated through the model's curvature" in t for t in sentences(with_term))
    assert any("curvature_samples = 0" in t for t in sentences(without))


def _field(alpha_nodes=(-4.0, 2.0, 8.0, 14.0), eta_nodes=(0.2, 0.5, 0.8, 1.0)):
    from calib.parametrizations import CorrectionField

    grid = CorrectionGrid(alpha_nodes, eta_nodes)
    return CorrectionField(grid.parameters()), grid


def test_node_correlation_of_the_smooth_field_prior():
    field, grid = _field()
    R = field.node_correlation(1.0)
    n = grid.n_lift
    np.testing.assert_allclose(np.diag(R), 1.0)
    np.testing.assert_allclose(R, R.T)
    assert np.linalg.eigvalsh(R).min() > -1e-10
    assert np.all(R[:n, n:] == 0.0)                       # lift and drag independent
    # neighbours one α spacing apart (uniform α nodes) at the same η: exp(-1/2)
    i, j = 0 * grid.n_eta + 1, 1 * grid.n_eta + 1
    assert R[i, j] == pytest.approx(np.exp(-0.5))
    np.testing.assert_allclose(field.node_correlation(0.0), np.eye(field.n_params))


@pytest.mark.parametrize("length", [0.7, 1.0, 2.0])
def test_representation_variance_is_the_interpolation_error_of_a_smooth_field(length):
    """Monte Carlo: draw the field of the smooth-field prior jointly at the nodes and at test
    points, interpolate the nodes with the hat functions, and compare the variance of the
    interpolation error with the closed form (zero at a node, the prior far from the grid)."""
    field, grid = _field()
    la, le = field.between_node_lengths(length)
    a_test = np.array([5.0, 3.5, 8.0, 11.0, 17.0, 40.0])     # cell centre, inside, node, ..., ramp, far
    e_test = np.array([0.65, 0.3, 0.5, 0.95, 0.6, 0.6])
    An, En = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    a_all = np.concatenate([An.ravel(), a_test])
    e_all = np.concatenate([En.ravel(), e_test])
    K = np.exp(-0.5 * ((a_all[:, None] - a_all[None]) / la) ** 2 - 0.5 * ((e_all[:, None] - e_all[None]) / le) ** 2)
    sigma = 0.1
    draws = sigma * np.random.default_rng(7004).multivariate_normal(np.zeros(a_all.size), K, 40000,
                                                                      method="eigh")
    B = field.basis(a_test, e_test, "lift")[:, :grid.n_lift]
    err = draws[:, grid.n_lift:] - draws[:, :grid.n_lift] @ B.T
    empirical = err.var(axis=0)
    prior_std = np.full(field.n_params, sigma)
    formula = field.representation_variance(a_test, e_test, "lift", prior_std, length)
    np.testing.assert_allclose(formula, empirical, rtol=0.05, atol=1e-4 * sigma ** 2)
    assert formula[2] == pytest.approx(0.0, abs=1e-12) and formula[-1] == pytest.approx(sigma ** 2)
    # the smooth field is far better carried between the nodes than independent nodes claim
    rough = field.representation_variance(a_test, e_test, "lift", prior_std, 0.0)
    assert formula[0] < 0.5 * rough[0] and rough[0] == pytest.approx(0.75 * sigma ** 2)


@pytest.mark.parametrize("mu, s, lower", [(0.0, 1.0, -np.inf), (0.0, 1.0, -3.0), (0.0, 1.0, -1.0),
                                           (0.02, 0.01, 0.015), (-0.004, 0.01, -0.003), (0.0, 1.0, 4.0)])
def test_bounded_interval_is_the_shortest_interval_of_the_truncated_gaussian(mu, s, lower):
    """The band under a bound: probability 0.95 under the Gaussian truncated at the bound
    (exact and by sampling scipy's truncnorm), no point below the bound, and no shorter
    interval of that probability (a search over the lower end)."""
    from scipy import stats

    from calib.parametrizations.field_bands import bounded_interval

    lo, hi = (float(v) for v in bounded_interval(mu, s, lower, 0.95))
    mass = stats.norm.sf((lower - mu) / s)

    def prob(a, b):
        return (stats.norm.cdf((b - mu) / s) - stats.norm.cdf((max(a, lower) - mu) / s)) / mass

    assert prob(lo, hi) == pytest.approx(0.95, abs=1e-9)
    assert lo >= lower
    if lower == -np.inf:
        assert (lo, hi) == pytest.approx((mu - 1.959964 * s, mu + 1.959964 * s), rel=1e-6)
    draws = stats.truncnorm.rvs((lower - mu) / s, np.inf, loc=mu, scale=s, size=200_000,
                                random_state=np.random.default_rng(7005))
    assert np.mean((draws >= lo) & (draws <= hi)) == pytest.approx(0.95, abs=0.003)
    # every other interval of the same probability is longer
    start = max(lower, mu - 6 * s)
    for a in np.linspace(start, lo + 2 * s, 401):
        target = stats.norm.cdf((max(a, lower) - mu) / s) + 0.95 * mass
        if target < 1:
            b = mu + s * stats.norm.ppf(target)
            assert b - a >= hi - lo - 1e-9 * s


def test_bounded_interval_far_in_the_tail_stays_finite():
    """An estimate 50σ below the bound (the Gaussian's mass above it underflows): the interval
    is the exponential tail's, [bound, bound + σ·ln 20 / 50], not infinite."""
    from calib.parametrizations.field_bands import bounded_interval

    lo, hi = bounded_interval(np.array([0.0, 0.0]), np.array([1.0, 1.0]), np.array([50.0, 30.0]))
    assert lo[0] == 50.0 and hi[0] == pytest.approx(50.0 + np.log(20.0) / 50.0, rel=1e-12)
    assert hi[1] == pytest.approx(30.0 + np.log(20.0) / 30.0, rel=2e-3)     # the exact quantile, near the limit


def test_the_drag_band_never_reaches_below_cd_min_and_coverage_counts_the_same_band():
    """With a nominal C_D of 0.006 and a prior-sized ΔC_D band (σ 0.01) the Gaussian band
    would reach C_D −0.014; bounded by C_D,min = 0.003 it starts there, its upper end is that
    of the truncated Gaussian, the lift band is unchanged, and the coverage count uses the
    same band (a truth below the bound is outside, one just under the upper end inside)."""
    from calib.parametrizations import CorrectionField
    from calib.parametrizations.field_bands import bounded_interval

    grid = CorrectionGrid([0.0, 6.0, 12.0], [0.3, 0.7])
    field = CorrectionField(grid.parameters(), nominal_coefficients=lambda a, e: (0.5 + 0 * np.asarray(a),
                                                                                  0.006 + 0 * np.asarray(a)))
    n = field.n_params
    std = np.r_[np.full(grid.n_lift, 0.1), np.full(grid.n_params - grid.n_lift, 0.01)]
    cov = np.diag(std ** 2)
    p = np.zeros(n)
    pb = field.bands(p, cov, cd_min=0.003)
    free = field.bands(p, cov, cd_min=None)
    np.testing.assert_allclose(pb["dcd_lower"], 0.003 - 0.006)                       # C_D band starts at 0.003
    assert np.all(pb["cd0"] + pb["dcd_lower"] >= 0.003 - 1e-15)
    assert np.all(free["cd0"] + free["dcd_lower"] < 0.0)                              # the Gaussian's is negative
    _, hi = bounded_interval(0.0, np.sqrt(np.einsum("ij,jk,ik->i", field.basis(6.0, 0.3, "drag"), cov,
                                                     field.basis(6.0, 0.3, "drag")))[0], -0.003)
    j = int(np.argmin(np.abs(pb["alpha_deg"] - 6.0)))
    assert pb["dcd_upper"][0, j] == pytest.approx(float(hi))
    assert np.all(pb["dcd_upper"] < free["dcd_upper"])                                # narrower, not shifted up
    np.testing.assert_allclose(pb["dcl_upper"] - pb["dcl"], pb["dcl_half_width"])     # lift: the Gaussian band
    np.testing.assert_allclose(pb["dcl"] - pb["dcl_lower"], pb["dcl_half_width"])
    a, e = np.array([6.0, 6.0, 6.0]), np.array([0.3, 0.3, 0.3])
    truth_dcd = np.array([-0.0035, 0.99 * float(hi), 1.01 * float(hi)])
    cover = [field.coverage(p, cov, a[[k]], e[[k]], np.zeros(1), truth_dcd[[k]], cd_min=0.003)["drag"]
             for k in range(3)]
    assert cover == [0.0, 1.0, 0.0]
    assert field.coverage(p, cov, a[:1], e[:1], np.zeros(1), truth_dcd[:1], cd_min=None)["drag"] == 1.0


def _held_back_chi2(res, model, cond, measured, sigma):
    pred = res.predict(cond, model=model)
    return float(np.mean(((measured - pred.values) / sigma) ** 2))


@pytest.fixture(scope="module")
def bem_twin():
    rotor = load_rotor("nrel5mw")
    grid = CorrectionGrid([-4.0, 2.0, 8.0, 14.0], [0.3, 0.6, 1.0])
    channels = ("power", "thrust", "root_flap_moment")
    model = BemModel(rotor, grid, channels, BemSettings(use_tilt=False), nuisance=("pitch_offset", "wind_scale"))
    tsr, pitch = np.meshgrid(np.linspace(4.5, 10.5, 7), [-1.0, 1.5, 4.0, 6.5], indexing="ij")
    rpm = 11.0
    v = rpm * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, rpm), pitch.ravel())
    return model, cond, grid


def _nuisance_z(res, truth):
    return {v["name"]: (v["value"] - truth.get(v["name"], v["nominal"])) / v["std"]
            for v in res.identifiability.verdicts if v["kind"] == "nuisance"}


def test_pure_polar_change_is_not_absorbed_by_the_nuisance_parameters(bem_twin):
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    p[:grid.n_lift] = (-0.12 * np.exp(-0.5 * ((A - 8) / 5) ** 2) * (E > 0.5)).ravel()
    for seed in (7010, 7011, 7012):
        meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=seed)
        res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=0.003)).run()
        z = _nuisance_z(res, {})
        assert all(abs(v) <= 3.0 for v in z.values()), (seed, z)


def test_pure_pitch_offset_is_recovered_within_three_sigma(bem_twin):
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    j = [q.name for q in model.parameters].index("pitch_offset")
    p[j] = 1.5
    for seed in (7020, 7021, 7022):
        meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=seed)
        res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=0.003)).run()
        z = _nuisance_z(res, {"pitch_offset": 1.5})
        assert abs(z["pitch_offset"]) <= 3.0 and abs(z["wind_scale"]) <= 3.0, (seed, z)
        # the report says how much the pitch offset shares with the field instead of hiding it
        v = next(v for v in res.identifiability.verdicts if v["name"] == "pitch_offset")
        assert 0.0 <= v["shared_information"] <= 1.0 and "confounded_with" in v


def test_goodness_of_fit_counts_dof_right(bem_twin):
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = -0.05
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7030)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=0.003)).run()
    gof = res.goodness_of_fit()
    n = len(cond) * len(model.channels)
    assert gof["dof_before"] == n and gof["dof_after"] == n - res.n_retained
    assert gof["chi2_per_dof_before"] == pytest.approx(res.fit.chi2_before / n)
    assert 0.0 <= gof["p_value_after"] <= 1.0 and len(gof["worst"]) == 5
    assert abs(gof["worst"][0]["whitened_residual"]) >= abs(gof["worst"][-1]["whitened_residual"])


def test_prediction_intervals_cover_the_noise_free_truth(bem_twin, tmp_path):
    """Calibrate, then `calib predict` at conditions between the calibration points: the
    95 % intervals of the model output contain the noise-free truth at >= 90 % of them."""
    model, cond, grid = bem_twin
    p = nominal_vector(model.parameters)
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    p[:grid.n_lift] = (0.08 * np.sin(np.radians(A) * 6) * E).ravel()
    p[grid.n_lift:grid.n_params] = 0.003 * (A > 10).ravel()
    p[[q.name for q in model.parameters].index("pitch_offset")] = 0.4
    meas = synthesize(model, p, cond, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7040)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=0.003)).run()
    res.save(tmp_path / "res")
    tsr, pitch = np.meshgrid(np.linspace(5.0, 10.0, 6), [0.0, 2.5, 5.0], indexing="ij")
    v = 11.0 * np.pi / 30 * model.rotor.rotor_radius / tsr.ravel()
    new = OperatingConditions(v, np.full(v.size, 11.0), pitch.ravel())
    truth = model.evaluate(p, new).values
    noisy = synthesize(model, p, new, relative_sigma={c.name: 0.01 for c in model.channels}, seed=7041)
    noisy.write_csv(tmp_path / "new.csv")
    out = tmp_path / "pred.csv"
    assert cli_main(["predict", str(tmp_path / "res"), "--data", str(tmp_path / "new.csv"), "--out", str(out)]) == 0
    import csv
    rows = [r for r in csv.reader(open(out)) if r and not r[0].startswith("#")]
    header = rows[0]
    n_numbers = header.index("status")                   # then status, envelope, outside_because
    body = np.array([[float(x) for x in r[:n_numbers]] for r in rows[1:]])
    inside = []
    for j, c in enumerate(res.channels):
        col = header.index(f"{c} [{res.channel_units[j]}]")
        lo, hi = body[:, col + 1], body[:, col + 2]
        assert np.all(lo <= body[:, col]) and np.all(body[:, col] <= hi)
        inside.append((truth[:, j] >= lo) & (truth[:, j] <= hi))
    assert np.mean(inside) >= 0.9, np.mean(inside, axis=1)
    # the result reloads with everything the predictions need
    back = load_result(tmp_path / "res")
    np.testing.assert_allclose(back.predict(new).values, res.predict(new).values)


@pytest.mark.slow
@pytest.mark.parametrize("workflow, stage", [("blade_loads_localization.toml", 1)])
def test_auto_truncation_on_the_shipped_workflows_held_back(workflow, stage):
    """The shipped localization study, every third operating point held back: the automatic
    truncation predicts the held-back measurements within 20 % of the best σ̄ of a sweep
    0.1 … 5. (The wind-tunnel study sits at the limit, ratio 1.20: ``bench_coverage.held_back``
    and docs/user_guide/calibration.md; it is not asserted here.)"""
    from pathlib import Path

    from calib.workflow import load_workflow, prepare, synthetic_conditions, truth_model

    loaded = load_workflow(Path(__file__).resolve().parents[1] / "workflows" / workflow)
    setup = prepare(loaded)
    cond = synthetic_conditions(loaded.conditions, setup.rotor, setup.density)
    grid = setup.grid(cond)
    channels = list(loaded.stages[stage].channels)
    tmodel, p_true = truth_model(setup.rotor, channels, setup.settings, loaded.truth, setup.nuisance)
    rel = {c: float(loaded.noise.relative[c]) for c in channels}
    meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels, seed=7100)
    model = BemModel(setup.rotor, grid, channels, setup.settings, setup.nuisance)
    test = np.arange(len(cond)) % 3 == 1
    train = type(meas)(cond.subset(~test), meas.channels, meas.values[~test], meas.sigma[~test], "train")
    scores = {}
    for sb in ("auto", 0.1, 0.3, 1.0, 2.0, 5.0):
        st = dataclasses.replace(setup.calibration, sigma_bar=sb, estimator="truncated")   # σ̄: its setting
        res = Calibrator(model, train, st).run()
        scores[sb] = _held_back_chi2(res, model, cond.subset(test), meas.values[test], meas.sigma[test])
    best = min(v for k, v in scores.items() if k != "auto")
    assert scores["auto"] <= 1.2 * best, scores


def _bench():
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import bench_coverage

    return bench_coverage


def test_auto_truncation_on_a_held_back_split_of_the_analytic_twin():
    """The analytic twin (56 points, every third held back): the automatic truncation predicts
    the held-back measurements within 20 % of the best σ̄ of a sweep 0.1 … 5."""
    fig = _bench().held_back("twin", sweep=(0.1, 0.3, 0.5, 1.0, 2.0, 5.0), seed=7110)
    assert fig["ratio"] <= 1.2, fig


def test_held_back_splits_of_the_workflow_grid():
    """On the workflows' grid (12 tip-speed ratios × 6 pitches, pitch the inner loop): ``rows``
    holds back the whole pitch lines 2 and 5 (0° and 6° in the wind tunnel), ``interleaved`` a
    third of every pitch line and of every tip-speed ratio."""
    mask = _bench().held_back_mask
    rows, inter = mask(72, "rows").reshape(12, 6), mask(72, "interleaved").reshape(12, 6)
    assert rows.sum() == inter.sum() == 24
    np.testing.assert_array_equal(rows.all(axis=0), [False, True, False, False, True, False])
    assert not rows[:, [0, 2, 3, 5]].any()
    np.testing.assert_array_equal(inter.sum(axis=0), 4)
    np.testing.assert_array_equal(inter.sum(axis=1), 2)
    with pytest.raises(ValueError, match="split"):
        mask(72, "random")


@pytest.fixture(scope="module")
def coverage_twins():
    """benchmarks/bench_coverage.py twins (a) inside the span, (b) outside it, (c) truths drawn
    from the prior at the nodes, (d) truths drawn from the prior on a fine grid; noise seeds
    7300–7309, used nowhere else and not used to choose the method. The truncated estimator: these
    tests check its retained θ, frozen directions and curvature term (pinned since MAP became the default)."""
    return _bench().coverage(10, seed0=7300, estimator="truncated")


@pytest.mark.statistics
def test_polar_bands_cover_the_truth_in_the_coverage_twins(coverage_twins):
    """Honest bands: at least 90 % of the reached (α, η) points inside the 95 % bands in every
    twin."""
    for name, fig in coverage_twins.items():
        assert fig["coverage_lift_mean"] >= 0.90 and fig["coverage_drag_mean"] >= 0.90, (name, fig)


@pytest.mark.statistics
@pytest.mark.parametrize("name", [
    pytest.param("c_prior_draws", marks=pytest.mark.xfail(
        reason="issue 7: on these seeds (c) covers ΔC_L at 99.7 % and ΔC_D at 99.6 % (seeds 5000-5029: 98.8 %, "
               "97.7 %; tuning seeds 8300-8329: 98.7 %, 96.8 %): the default bands budget a field between the nodes "
               "that truths in the span lack (NEES 50.0 for 170, docs/user_guide/calibration.md)",
        strict=False)),
    "d_prior_draws_outside_span"])
def test_polar_bands_are_not_wider_than_needed_for_truths_drawn_from_the_prior(coverage_twins, name):
    fig = coverage_twins[name]
    assert fig["coverage_lift_mean"] <= 0.99 and fig["coverage_drag_mean"] <= 0.99, fig


@pytest.mark.statistics
@pytest.mark.xfail(reason="a fixed truth that is zero where the data say little: the bands there are the prior's and "
                          "cover 99.98-100 % of the reached points in twins (a) and (b) (bench_coverage, seeds "
                          "5000-5029); see docs/user_guide/calibration.md", strict=False)
@pytest.mark.parametrize("name", ["a_inside_span", "b_outside_span"])
def test_polar_bands_are_not_wider_than_needed_for_the_workflow_truth(coverage_twins, name):
    fig = coverage_twins[name]
    assert fig["coverage_lift_mean"] <= 0.99 and fig["coverage_drag_mean"] <= 0.99, fig


@pytest.mark.statistics
@pytest.mark.parametrize("name", ["b_outside_span", "d_prior_draws_outside_span"])
def test_nees_of_the_retained_theta_in_its_chi2_band(coverage_twins, name):
    """Truths outside the span of the hat functions (as real polars are): the summed NEES of
    the retained θ against the truth's values at the nodes, with the covariance the result
    states, over the calibrations that ended "converged" (a result that did not says in its
    message that its σ can be too narrow), inside the two-sided 95 % χ² band; at least half
    of the ten must have converged."""
    fig = coverage_twins[name]
    assert fig["n_seeds"] - len(fig["nees_not_converged"]) >= 5, fig
    assert fig["nees_converged_band"][0] <= fig["nees_converged_sum"] <= fig["nees_converged_band"][1], fig


@pytest.mark.statistics
@pytest.mark.parametrize("name", ["a_inside_span", "c_prior_draws"])
def test_nees_of_the_retained_theta_is_not_overconfident_for_truths_in_the_span(coverage_twins, name):
    """Truths exactly in the span of the hat functions: the stated covariance carries the
    aliasing of a field between the nodes that these truths lack, so the NEES is below its
    dimension (conservative, docs/user_guide/calibration.md); it must not exceed the band's upper end."""
    fig = coverage_twins[name]
    assert fig["nees_converged_sum"] <= fig["nees_converged_band"][1], fig


@pytest.mark.statistics
def test_prior_check_holds_the_stated_amplitude_for_truths_drawn_from_that_prior(coverage_twins):
    """Twin (d) draws its truth from the very prior the check assumes (a smooth field on a fine
    grid): the 95 % interval of the field's amplitude must contain the stated 1 in at least 8 of
    the 10 draws (7 or fewer has probability 1.2 % for an interval that is right)."""
    fig = coverage_twins["d_prior_draws_outside_span"]
    assert fig["prior_check_contains_stated"] >= 0.8, fig


@pytest.fixture(scope="module")
def coverage_twins_stated_in_span():
    """Twins (a) and (c), whose truths lie in the span of the hat functions, calibrated with the
    user's statement that they do (``representation_error = false``); seeds 7300–7309; the
    truncated estimator, as :func:`coverage_twins`."""
    return _bench().coverage(10, seed0=7300, twins="ac", representation_error=False, estimator="truncated")


@pytest.mark.statistics
def test_nees_in_its_chi2_band_for_prior_draws_stated_to_lie_in_the_span(coverage_twins_stated_in_span):
    """With no field between the nodes budgeted, the retained θ of truths drawn from the prior
    in the span, twin (c), must be neither over- nor underconfident: summed NEES over all ten
    calibrations inside the two-sided 95 % χ² band. Without the curvature term
    (``curvature_samples = 0``) it was 172.8 for 131 (band 101–165) here: the runs that keep
    5–8 θ leave a prior-sized truth frozen, and the model's curvature turns it into a bias of
    the retained θ."""
    fig = coverage_twins_stated_in_span["c_prior_draws"]
    assert fig["nees_band"][0] <= fig["nees_sum"] <= fig["nees_band"][1], fig


@pytest.mark.statistics
def test_nees_is_not_overconfident_for_the_workflow_truth_stated_to_lie_in_the_span(coverage_twins_stated_in_span):
    """Twin (a), the workflow's fixed truth at the nodes, is zero where the data say little, so
    the prior-sized frozen part that the curvature term budgets for is larger than this
    truth's: its NEES may fall below the band (docs/user_guide/calibration.md) but must not exceed it."""
    fig = coverage_twins_stated_in_span["a_inside_span"]
    assert fig["nees_sum"] <= fig["nees_band"][1], fig


@pytest.mark.statistics
@pytest.mark.parametrize("name", [
    pytest.param("wind_tunnel", marks=pytest.mark.xfail(
        reason="issue 7: the automatic choice (12 θ, held-back χ²/dof 2.229) against the sweep's best (σ̄ = 0.5, "
               "18 θ, 1.858) is a ratio of 1.1997 on this seed (2026-11-27, truncated estimator): at the limit, so "
               "round-off across CPUs decides pass or fail (not strict); on six tuning draws (8240-8245) the ratio "
               "is 1.07-1.79, so the target is not met in general (docs/user_guide/calibration.md)", strict=False)),
    "twin"])
def test_auto_truncation_held_back_on_the_shipped_data(name):
    """As the localization test above, on the wind-tunnel study's own noise seed and on another
    noise draw of the analytic twin."""
    fig = _bench().held_back(name)
    assert fig["ratio"] <= 1.2, fig


def test_a_result_whose_retained_set_did_not_settle_says_its_bands_can_be_too_narrow():
    """A stability test no re-linearization can pass (cosine 1 - 1e-12): the status is
    not_stable, and the message gives the angle the retained set still turns by and tells the
    user not to trust the stated σ."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    model = TwinModel(channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 4))
    meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=7120)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None, max_relinearizations=2,
                                                      stability_cosine=1.0 - 1e-12)).run()
    assert res.estimate.status == "not_stable"
    assert "can be too narrow" in res.estimate.message and "sigma_bar" in res.estimate.message
    assert "after 2 re-linearizations; between the last two re-linearizations" in res.estimate.message
    assert "turned by" in res.estimate.message


def test_the_last_allowed_re_linearization_is_checked_for_stability():
    """The re-linearization of the last estimate allowed is compared with the set it was
    estimated on: with one re-linearization, a retained set that settled is "converged" (it was
    reported not_stable without being checked)."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    model = TwinModel(channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 4))
    meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=7120)
    one = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None, max_relinearizations=1)).run()
    more = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None)).run()
    assert more.estimate.status == "converged" and "stable after 1 re-linearization(s)" in more.estimate.message
    assert one.estimate.status == "converged" and "stable after 1 re-linearization(s)" in one.estimate.message
    np.testing.assert_allclose(one.estimate.p_hat, more.estimate.p_hat)


def test_misfit_beyond_the_stated_noise_scales_the_retained_covariance():
    """Data with twice the stated noise: χ²/dof after near 4 and the covariance of the retained
    θ multiplied by it (the frozen prior part not); off with scale_by_fit = false."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    model = TwinModel(channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 7))
    meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.02 for c in CHANNELS}, seed=7130)
    stated = type(meas)(meas.conditions, meas.channels, meas.values, 0.5 * meas.sigma, "stated half")
    base = CalibrationSettings(estimator="truncated", cd_min=None, sigma_bar=1.0)
    res = Calibrator(model, stated, base).run()
    off = Calibrator(model, stated, dataclasses.replace(base, scale_by_fit=False)).run()
    ratio = res.fit.chi2_after / res.dof
    assert 2.5 < ratio < 6.0
    assert res.uncertainty.fit_scale == pytest.approx(ratio) and off.uncertainty.fit_scale == 1.0
    np.testing.assert_allclose(res.uncertainty.cov_theta, ratio * off.uncertainty.cov_theta, rtol=1e-9)
    np.testing.assert_allclose(res.uncertainty.cov_frozen, off.uncertainty.cov_frozen, rtol=1e-9, atol=1e-15)
    # a fit consistent with its noise is left alone
    fine = Calibrator(model, meas, base).run()
    assert fine.uncertainty.fit_scale == max(1.0, fine.fit.chi2_after / fine.dof) and fine.uncertainty.fit_scale < 1.5


def test_a_calibration_whose_estimator_did_not_move_is_not_called_converged(monkeypatch):
    """An estimator that stops where no step decreases the cost leaves the retained set
    unchanged, which the re-linearization loop would read as stable: the status is
    "stalled" and the message says the σ are not those of a minimum."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    import calib.calibration.truncated_fit as cal
    from calib.calibration.gauss_newton import EstimationOutcome

    def no_step(problem, basis, theta0, *args, **kwargs):
        start = problem.linearize(problem.p_of(basis, theta0))
        return EstimationOutcome(np.asarray(theta0, float), start.p, start.cost, 0, "stalled",
                                 "no step decreased the cost (damping exhausted)", start)

    monkeypatch.setattr(cal, "estimate_ml", no_step)
    model = TwinModel(channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 5))
    meas = synthesize(model, twin_truth(model), cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=7121)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None, sigma_bar=1.0)).run()
    assert res.estimate.status == "stalled", res.message
    assert "not of a minimum" in res.estimate.message
    np.testing.assert_allclose(res.estimate.p_hat, res.estimate.p_nominal)


def test_bands_that_leave_out_the_field_between_the_nodes_say_so(bem_twin, tmp_path):
    """A field model that cannot be rebuilt on a finer grid (the analytic twin, as an FMU) and a
    BEM run with representation_error = false carry a note on what their bands leave out, the
    report states it and it survives saving; the default BEM run includes the term and has none."""
    from test_calibration import CHANNELS, twin_truth
    from twin_model import TwinModel, twin_conditions

    from calib.report.result_sentences import sentences

    model = TwinModel(channels=CHANNELS)
    meas = synthesize(model, twin_truth(model), twin_conditions(tsr=np.linspace(4.0, 10.0, 5)),
                      relative_sigma={c: 0.01 for c in CHANNELS}, seed=7123)
    res = Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None, sigma_bar=1.0)).run()
    assert res.uncertainty.aliasing_chi2 == 0.0 and "cannot be rebuilt on a finer correction grid" in res.uncertainty.aliasing_note
    assert any(t.startswith("Not in the bands: ") and "TwinModel" in t for t in sentences(res))
    res.save(tmp_path)
    assert load_result(tmp_path).uncertainty.aliasing_note == res.uncertainty.aliasing_note

    bem, cond, grid = bem_twin
    p = nominal_vector(bem.parameters)
    p[:grid.n_lift] = -0.05
    meas = synthesize(bem, p, cond, relative_sigma={c.name: 0.01 for c in bem.channels}, seed=7124)
    on = Calibrator(bem, meas, CalibrationSettings(estimator="truncated", cd_min=0.003, sigma_bar=1.0)).run()
    assert on.uncertainty.aliasing_note == "" and on.uncertainty.aliasing_chi2 > 0.0
    assert not any(t.startswith("Not in the bands") for t in sentences(on))
    off = Calibrator(bem, meas, CalibrationSettings(estimator="truncated", cd_min=0.003, sigma_bar=1.0,
                                                    representation_error=False)).run()
    assert "representation_error = false" in off.uncertainty.aliasing_note and off.uncertainty.aliasing_chi2 == 0.0


@pytest.fixture(scope="module")
def coverage_twins_map():
    """Twins (c) and (d), truths drawn from the stated prior, calibrated by the MAP estimator (the
    default since 2026-11-25); seeds 7300–7309."""
    return _bench().coverage(10, seed0=7300, twins="cd", estimator="map")


@pytest.fixture(scope="module")
def coverage_twins_map_in_span():
    """Twin (c) by the MAP with the user's statement that the truths lie in the span
    (``representation_error = false``); seeds 7300–7309."""
    return _bench().coverage(10, seed0=7300, twins="c", estimator="map", representation_error=False)


def _full_vector_nees(fig):
    lo, hi = fig["nees_full_vector_band"]
    return lo, fig["nees_full_vector_sum"], hi


@pytest.mark.statistics
def test_the_map_posterior_nees_of_prior_draws_is_in_its_chi2_band(coverage_twins_map, coverage_twins_map_in_span):
    """The MAP's premise: for truths drawn from the prior it states, the NEES of the whole scaled
    vector with the stated covariance, summed over ten calibrations, lies inside the two-sided 95 %
    χ² band: twin (d), whose truths vary between the nodes as the default bands assume, and twin (c),
    whose truths lie in the span, calibrated with that statement. (The retained-θ NEES of the tests
    above is the truncated estimator's: the MAP has no retained set.)"""
    for fig in (coverage_twins_map["d_prior_draws_outside_span"], coverage_twins_map_in_span["c_prior_draws"]):
        lo, nees, hi = _full_vector_nees(fig)
        assert lo <= nees <= hi, fig


@pytest.mark.statistics
def test_the_map_is_not_overconfident_for_prior_draws_in_the_span(coverage_twins_map):
    """Twin (c) under the default bands: they budget a field between the nodes that these truths
    lack, so the NEES may fall below the band (conservative, as the truncated estimator's) but must
    not exceed it."""
    lo, nees, hi = _full_vector_nees(coverage_twins_map["c_prior_draws"])
    assert nees <= hi, (lo, nees, hi)


def test_quadratic_diagonal_is_the_diagonal_of_the_sandwich():
    """The bands' per-point variance diag(B C Bᵀ) (field_bands.quadratic_diagonal) against the
    explicit product's diagonal, for a sparse hat-like B and a covariance C."""
    from calib.parametrizations.field_bands import quadratic_diagonal

    rng = np.random.default_rng(7420)
    B = np.where(rng.random((40, 12)) < 0.3, rng.random((40, 12)), 0.0)
    A = rng.standard_normal((12, 12))
    C = A @ A.T
    np.testing.assert_allclose(quadratic_diagonal(B, C), np.diag(B @ C @ B.T), rtol=1e-12, atol=1e-14)


def test_between_node_variance_falls_as_the_grid_is_refined_and_stays_on_a_coarse_grid():
    """Issue 41: the field between the nodes has physical lengths (prior_correlation × the longer of the
    grid's spacing and REFERENCE_SPACING). Halfway between two α nodes on an η node line, the interpolation
    error of a field of correlation ρ(Δα) = exp(−Δα²/2ℓ²) has relative variance
    1 − 2 exp(−h²/8ℓ²) + ½(1 + exp(−h²/2ℓ²)) (hand closed form): with ℓ = h on grids coarser than the
    reference (unchanged by refining to the reference), with ℓ = 6° (fixed) on finer ones, where it falls
    about as (h/ℓ)⁴."""
    from calib.parametrizations.field_prior import REFERENCE_SPACING

    def closed(h, ell):
        return 1.0 - 2.0 * np.exp(-h ** 2 / (8 * ell ** 2)) + 0.5 * (1.0 + np.exp(-h ** 2 / (2 * ell ** 2)))

    assert REFERENCE_SPACING[0] == 6.0
    rel = {}
    for h in (12.0, 8.0, 6.0, 3.0, 1.5):
        field, grid = _field(tuple(np.arange(-6.0, 18.0 + 1e-9, h)), (0.2, 0.4, 0.6, 0.8, 1.0))
        a = grid.alpha_nodes_deg[1] + 0.5 * h
        rel[h] = float(field.representation_variance(a, 0.6, "lift", np.full(field.n_params, 1.0), 1.0)[0])
        assert rel[h] == pytest.approx(closed(h, max(h, 6.0)), rel=1e-9), h
    assert rel[12.0] == pytest.approx(rel[6.0]) and rel[6.0] == pytest.approx(0.0383, abs=5e-4)   # coarse: kept
    assert rel[6.0] > 10 * rel[3.0] > 100 * rel[1.5]                                               # refined: falls
