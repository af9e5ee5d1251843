"""Fisher matrix, Cramér–Rao bound, whitened SVD, selection, eigenshapes and verdicts."""

import numpy as np
import pytest

from calib.calibration.identifiability import (cramer_rao, fisher_matrix, observability, parameter_verdicts,
                                               sigma_bar_for, subspace_cosines, svd_analysis, whitened_sensitivities)
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.models.base import Parameter
from calib.parametrizations.correction_field import eigenshapes, field_basis, node_layout

GRID = CorrectionGrid([-4.0, 4.0, 12.0, 20.0], [0.25, 0.6, 1.0])
NUISANCE = Parameter("pitch_offset", 0.0, -5.0, 5.0, 0.5, "deg", "nuisance")
PARAMS = GRID.parameters() + (NUISANCE,)


def test_whitened_sensitivities_scale_whiten_and_zero_failed_points():
    rng = np.random.default_rng(0)
    G = rng.standard_normal((5, 2, 3))
    sigma = np.array([[1.0, 2.0]] * 5)
    scale = np.array([0.1, 1.0, 10.0])
    ok = np.array([True, True, False, True, True])
    M = whitened_sensitivities(G, sigma, scale, ok)
    assert M.shape == (10, 3)
    np.testing.assert_allclose(M[1], G[0, 1] * scale / 2.0)       # point 0, channel 1
    assert np.all(M[4:6] == 0.0)                                    # failed point 2
    np.testing.assert_allclose(fisher_matrix(M), M.T @ M)


def test_cramer_rao_full_rank_is_the_inverse_with_unit_diagonal_correlation():
    rng = np.random.default_rng(1)
    M = rng.standard_normal((20, 4))
    F = fisher_matrix(M)
    cov, std, corr = cramer_rao(F)
    np.testing.assert_allclose(cov, np.linalg.inv(F), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(std, np.sqrt(np.diag(np.linalg.inv(F))))
    np.testing.assert_allclose(np.diag(corr), 1.0)
    np.testing.assert_allclose(corr, corr.T)
    assert np.all(np.abs(corr) <= 1 + 1e-12)


def test_cramer_rao_unobservable_parameter_has_infinite_variance():
    rng = np.random.default_rng(2)
    M = rng.standard_normal((20, 4))
    M[:, 3] = 0.0                     # the data do not see parameter 3
    cov, std, corr = cramer_rao(fisher_matrix(M))
    assert np.isinf(std[3]) and np.all(np.isfinite(std[:3]))
    assert np.all(np.isnan(corr[3])) and np.all(np.isnan(corr[:, 3]))


def test_svd_analysis_reproduces_fisher_and_selects_by_threshold():
    rng = np.random.default_rng(3)
    M = rng.standard_normal((30, 5)) * np.array([10.0, 3.0, 1.0, 0.3, 0.01])
    svd = svd_analysis(M, sigma_bar=1.0)
    S2 = np.diag(svd.singular_values ** 2)
    np.testing.assert_allclose(svd.V @ S2 @ svd.V.T, fisher_matrix(M), atol=1e-9)
    np.testing.assert_allclose(svd.V.T @ svd.V, np.eye(5), atol=1e-12)
    np.testing.assert_allclose(svd.sigma_theta, 1.0 / svd.singular_values)
    assert np.array_equal(svd.retained, svd.sigma_theta <= 1.0)
    assert np.all(np.diff(svd.singular_values) <= 0)
    # the new parameters are statistically independent: Fisher of θ is diag(s²)
    Mt = M @ svd.V
    np.testing.assert_allclose(Mt.T @ Mt, S2, atol=1e-9)
    # monotone in σ̄, capped by max_retained
    counts = [svd_analysis(M, sb).n_retained for sb in (0.01, 0.1, 1.0, 10.0, 1e3)]
    assert counts == sorted(counts) and counts[-1] == 5
    assert svd_analysis(M, 1e3, max_retained=2).n_retained == 2
    assert svd_analysis(M, 1.0).basis.shape == (5, svd.n_retained)


def test_svd_analysis_never_retains_null_directions_and_rejects_bad_threshold():
    M = np.zeros((10, 3))
    M[:, 0] = 1.0
    svd = svd_analysis(M, sigma_bar=np.inf)
    assert svd.n_retained == 1 and np.isinf(svd.sigma_theta[1:]).all()
    with pytest.raises(InputError, match="sigma_bar"):
        svd_analysis(M, sigma_bar=0.0)


def test_sigma_bar_for_two_sided_confidence():
    assert sigma_bar_for(1.959964, 0.95) == pytest.approx(1.0, rel=1e-5)
    assert sigma_bar_for(0.2, 0.99) < sigma_bar_for(0.2, 0.9)


def test_subspace_cosines():
    Q = np.linalg.qr(np.random.default_rng(4).standard_normal((6, 6)))[0]
    np.testing.assert_allclose(subspace_cosines(Q[:, :2], Q[:, [1, 0]]), 1.0)
    np.testing.assert_allclose(subspace_cosines(Q[:, :2], Q[:, 2:4]), 0.0, atol=1e-12)


def test_node_layout_rebuilds_the_grid_from_parameters():
    layout = node_layout(PARAMS)
    np.testing.assert_allclose(layout.grid.alpha_nodes_deg, GRID.alpha_nodes_deg)
    np.testing.assert_allclose(layout.grid.eta_nodes, GRID.eta_nodes)
    for i in range(GRID.n_alpha):
        for j in range(GRID.n_eta):
            assert layout.lift_index[i, j] == GRID.node_index(i, j)
            assert layout.drag_index[i, j] == GRID.n_lift + GRID.node_index(i, j)
    assert not node_layout((NUISANCE,)).has_field


def test_field_basis_matches_the_correction_grid():
    layout = node_layout(PARAMS)
    rng = np.random.default_rng(5)
    p = rng.standard_normal(len(PARAMS))
    a = rng.uniform(-6, 22, 50)
    e = rng.uniform(0.2, 1.0, 50)
    dcl, dcd, _, _ = GRID.evaluate(p[:GRID.n_params], a, e)
    np.testing.assert_allclose(field_basis(layout, a, e, "lift", len(PARAMS)) @ p, dcl, atol=1e-12)
    np.testing.assert_allclose(field_basis(layout, a, e, "drag", len(PARAMS)) @ p, dcd, atol=1e-12)


def test_eigenshape_at_a_node_is_the_singular_vector_entry():
    layout = node_layout(PARAMS)
    V = np.linalg.qr(np.random.default_rng(6).standard_normal((len(PARAMS), len(PARAMS))))[0]
    lift, drag = eigenshapes(V, layout, GRID.alpha_nodes_deg, GRID.eta_nodes, modes=[0, 3])
    assert lift.shape == (2, GRID.n_eta, GRID.n_alpha)
    for k, mode in enumerate([0, 3]):
        np.testing.assert_allclose(lift[k].T, V[layout.lift_index, mode], atol=1e-12)
        np.testing.assert_allclose(drag[k].T, V[layout.drag_index, mode], atol=1e-12)


def test_observability_and_verdicts():
    n = 4
    V = np.eye(n)
    retained = np.array([True, True, False, False])
    obs = observability(V, retained)
    np.testing.assert_allclose(obs, [1, 1, 0, 0])
    params = tuple(Parameter(f"q{j}", 0.0, -1.0, 1.0, 0.1) for j in range(n))
    p_hat = np.array([0.2, 1.0, 0.0, 0.5])
    prior = np.full(n, 0.1)
    std = np.array([0.01, 0.01, 0.1, 0.09])
    v = parameter_verdicts(params, p_hat, -np.ones(n), np.ones(n), std, prior, obs)
    assert [d["verdict"] for d in v] == ["identified", "at bound", "poorly observable", "poorly observable"]
    # an estimate far from nominal is never silent: the note says how far
    assert v[3]["note"].startswith("5.6σ") and v[2]["note"] == ""
    # a parameter sharing most of its information with others is "confounded", not "identified"
    conf = {"q0": {"shared_information": 0.9, "shared_with_field": 0.9, "region": "lift near η 0.8–1"}}
    v = parameter_verdicts(params, p_hat, -np.ones(n), np.ones(n), std, prior, obs, conf)
    assert v[0]["verdict"] == "confounded" and v[0]["confounded_with"] == "lift near η 0.8–1"



def test_confounding_states_no_correlation_where_round_off_makes_a_variance_negative():
    """A Fisher matrix of sensitivities spanning 11 decades (a water rotor's loads beside a pitch
    offset): inverting F + P⁻¹ gives some field nodes a variance ≤ 0 by round-off. Those nodes get
    no correlation, never a NaN, and the others keep theirs."""
    import warnings

    from calib.calibration.identifiability import confounding
    from calib.types import ParameterKind

    rng = np.random.default_rng(60)        # a draw whose inverse has negative diagonal entries
    G = rng.normal(size=(3, 7)) * 10.0 ** rng.uniform(-2, 9, size=7)
    params = [Parameter("pitch_offset", 0.0, -5.0, 5.0, 1.0)] + [
        Parameter(f"dcl_{i}", 0.0, -1.0, 1.0, 0.1, kind=ParameterKind.LIFT_CORRECTION, alpha_deg=float(i), eta=0.5)
        for i in range(6)]
    C = np.linalg.inv(G.T @ G + np.eye(7))
    if not np.any(np.diag(C)[1:] <= 0):         # the case this test is about (round-off differs by CPU)
        pytest.skip("this CPU's round-off leaves every variance of this draw positive")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        entry = confounding(G.T @ G, np.ones(7), params)["pitch_offset"]
    negative = {f"dcl_{i}" for i in np.flatnonzero(np.diag(C)[1:] <= 0)}
    assert entry["correlated_nodes"] and not negative & set(entry["correlated_nodes"])
