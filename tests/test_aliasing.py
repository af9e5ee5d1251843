"""The field between the nodes seen by the data (calib.parametrizations.aliasing).

Seeds here (7400+) are used nowhere else in the suite.
"""

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.corrections import CorrectionGrid
from calib.models.bem_model import BemModel
from calib.parametrizations.aliasing import discrepancy_correlation, interpolation_matrix, refined_grid, refined_nodes
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector

COARSE = CorrectionGrid([-4.0, 2.0, 8.0, 14.0, 20.0], [0.25, 0.45, 0.65, 0.85, 1.0])


def test_refined_nodes_split_every_interval_and_reach_the_range():
    x = refined_nodes(np.array([0.0, 3.0, 9.0]), 3, -2.5, 12.0)
    np.testing.assert_allclose(x[(x >= 0) & (x <= 9)], [0, 1, 2, 3, 5, 7, 9])
    assert x[0] <= -2.5 < x[1] and x[-1] >= 12.0 > x[-2]
    e = refined_nodes(np.array([0.25, 0.65, 1.0]), 2, 0.1, 1.3, clip=(0.0, 1.0))
    assert e.max() == pytest.approx(1.0) and e.min() <= 0.1 and e.min() >= 0.0


def test_fine_interpolant_reproduces_the_coarse_field():
    """The coarse hats are piecewise bilinear with kinks on the coarse nodes (and one spacing
    outside); the refined grid holds those nodes, so T reproduces the coarse field exactly."""
    fine = refined_grid(COARSE, np.array([-12.0, 30.0]), np.array([0.05, 1.0]))
    T = interpolation_matrix(COARSE, fine)
    p = np.random.default_rng(7400).standard_normal(COARSE.n_lift)
    a = np.linspace(-11.0, 29.0, 37)
    e = np.linspace(0.06, 1.0, 23)
    A, E = np.meshgrid(a, e, indexing="ij")
    coarse_vals, _, _, _ = COARSE.evaluate(np.concatenate([p, p]), A, E)
    fine_vals, _, _, _ = fine.evaluate(np.concatenate([T @ p, T @ p]), A, E)
    np.testing.assert_allclose(fine_vals, coarse_vals, atol=1e-12)


def test_discrepancy_correlation_against_monte_carlo():
    """δ = f_fine − T f_coarse of draws of the smooth field: empirical covariance against the
    closed form; zero where a fine node is a coarse node."""
    fine = refined_grid(COARSE, np.array([-6.0, 22.0]), np.array([0.2, 1.0]), factor=2)
    lengths = (6.0, 0.1875)
    D = discrepancy_correlation(COARSE, fine, lengths)
    A, E = np.meshgrid(fine.alpha_nodes_deg, fine.eta_nodes, indexing="ij")
    Ac, Ec = np.meshgrid(COARSE.alpha_nodes_deg, COARSE.eta_nodes, indexing="ij")
    x = np.concatenate([A.ravel(), Ac.ravel()])
    y = np.concatenate([E.ravel(), Ec.ravel()])
    K = np.exp(-0.5 * ((x[:, None] - x) / lengths[0]) ** 2 - 0.5 * ((y[:, None] - y) / lengths[1]) ** 2)
    w, Q = np.linalg.eigh(K)
    L = Q * np.sqrt(np.clip(w, 0, None))
    draws = L @ np.random.default_rng(7401).standard_normal((x.size, 20000))
    nf = A.size
    delta = draws[:nf] - interpolation_matrix(COARSE, fine) @ draws[nf:]
    emp = np.cov(delta)
    assert np.max(np.abs(emp - D)) < 0.03, np.max(np.abs(emp - D))
    on_node = np.isin(np.round(A.ravel(), 9), COARSE.alpha_nodes_deg) & np.isin(np.round(E.ravel(), 9),
                                                                                 COARSE.eta_nodes)
    assert np.allclose(np.diag(D)[on_node], 0.0, atol=1e-9)
    assert np.diag(D)[~on_node].min() > 0.0


def test_the_fine_model_jacobian_carries_the_coarse_one():
    """G_coarse = G_fine T (chain rule through the exact interpolation) at the fine vector that
    reproduces the coarse estimate; the outputs agree too."""
    rotor = load_rotor("phase_vi")
    model = BemModel(rotor, COARSE, ("power", "thrust"), BemSettings(use_tilt=False), ("pitch_offset",))
    assert model.capabilities.refinable and model.capabilities.correction_field
    cond = OperatingConditions(np.array([7.0, 10.0, 13.0]), np.full(3, 72.0), np.array([3.0, 3.0, 3.0]))
    rng = np.random.default_rng(7402)
    p = nominal_vector(model.parameters)
    p[:COARSE.n_lift] = 0.05 * rng.standard_normal(COARSE.n_lift)
    p[-1] = 0.3
    ev, G = model.jacobian(p, cond)
    fine = refined_grid(COARSE, ev.extras["alpha_deg"][np.isfinite(ev.extras["alpha_deg"])], rotor.eta)
    fmodel = model.with_grid(fine)
    T = interpolation_matrix(COARSE, fine)
    pf = nominal_vector(fmodel.parameters)
    pf[:fine.n_lift], pf[fine.n_lift:fine.n_params] = T @ p[:COARSE.n_lift], T @ p[COARSE.n_lift:COARSE.n_params]
    pf[-1] = p[-1]
    evf, Gf = fmodel.jacobian(pf, cond)
    np.testing.assert_allclose(evf.values, ev.values, rtol=1e-10)
    for block in range(2):
        gc = G[..., block * COARSE.n_lift:(block + 1) * COARSE.n_lift]
        gf = Gf[..., block * fine.n_lift:(block + 1) * fine.n_lift] @ T
        np.testing.assert_allclose(gf, gc, rtol=1e-8, atol=1e-8 * np.abs(gc).max())
    np.testing.assert_allclose(Gf[..., -1], G[..., -1], rtol=1e-10)


def test_aliasing_covariance_and_misfit_against_monte_carlo():
    """Draws of the field between the nodes (fine nodal values minus their coarse interpolant,
    from the closed-form covariance) pushed through the fine model's whitened sensitivities:
    the retained θ's one-step error S⁻²V_IDᵀMᵀWδ and the residual χ² it leaves match the
    function's covariance and expected misfit."""
    from calib.calibration.identifiability import whitened_sensitivities
    from calib.parametrizations.aliasing import aliasing_covariance

    rotor = load_rotor("phase_vi")
    model = BemModel(rotor, COARSE, ("power", "thrust"), BemSettings(use_tilt=False), ("pitch_offset",))
    tsr, pitch = np.meshgrid([3.0, 4.5, 6.0], [0.0, 4.0], indexing="ij")
    v = 72.0 * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, 72.0), pitch.ravel())
    p = nominal_vector(model.parameters)
    ev, G = model.jacobian(p, cond)
    sigma = 0.01 * np.abs(ev.values)
    scale = np.array([q.scale for q in model.parameters])
    M = whitened_sensitivities(G, sigma, scale, ev.ok)
    _, s, Vt = np.linalg.svd(M, full_matrices=False)
    k = 5
    alpha = ev.extras["alpha_deg"][:, ev.extras["interior"]]
    eta = np.broadcast_to(rotor.eta[ev.extras["interior"]], alpha.shape)
    prior_std = 1.0 * scale
    cov, misfit = aliasing_covariance(model, p, cond, sigma, [0, 1], ev.ok, M, Vt[:k].T, s[:k], prior_std, 1.0,
                                      alpha.ravel(), eta.ravel())
    # Monte Carlo with the same pieces
    fine = refined_grid(COARSE, alpha.ravel(), eta.ravel())
    fmodel = model.with_grid(fine)
    pf = nominal_vector(fmodel.parameters)
    _, Gf = fmodel.jacobian(pf, cond)
    W = (Gf[..., :fine.n_params] / sigma[:, :, None]).reshape(-1, fine.n_params)
    D = discrepancy_correlation(COARSE, fine, (6.0, 0.1875))
    w, Q = np.linalg.eigh(D)
    L = Q * np.sqrt(np.clip(w, 0, None))
    rng = np.random.default_rng(7403)
    n = fine.n_lift
    sd = np.array([COARSE.cl_scale, COARSE.cd_scale])
    draws = np.concatenate([sd[b] * (L @ rng.standard_normal((n, 4000))) for b in range(2)])
    y = W @ draws
    U = (M @ Vt[:k].T) / s[:k]
    theta = (Vt[:k] @ (M.T @ y)) / s[:k, None] ** 2
    resid = y - U @ (U.T @ y)
    assert np.mean(np.sum(resid ** 2, axis=0)) == pytest.approx(misfit, rel=0.1)
    np.testing.assert_allclose(np.cov(theta), cov, rtol=0.15, atol=0.05 * np.abs(np.diag(cov)).max())


def test_kronecker_square_root_of_the_grid_correlation():
    """L_α ⊗ L_η reproduces the squared-exponential correlation of every pair of grid nodes."""
    from calib.corrections import CorrectionGrid
    from calib.parametrizations.aliasing import grid_correlation, grid_correlation_sqrt

    g = CorrectionGrid(np.linspace(-6.0, 20.0, 9), [0.2, 0.35, 0.5, 0.8, 1.0])
    L = grid_correlation_sqrt(g, (4.0, 0.2))
    np.testing.assert_allclose(L @ L.T, grid_correlation(g, g, (4.0, 0.2)), atol=1e-12)


def test_structured_propagation_equals_the_dense_discrepancy_covariance():
    """discrepancy_propagated never forms Σ_δ (Kronecker factors and the coarse nodes instead): against
    B Σ_δ Bᵀ with the dense Σ_δ of discrepancy_correlation (checked by Monte Carlo above), per block
    with its own prior variance, full matrix and diagonal, for a random B."""
    from types import SimpleNamespace

    from calib.parametrizations.aliasing import discrepancy_propagated

    model = BemModel(load_rotor("phase_vi"), COARSE, ("power",), BemSettings(use_tilt=False), ("pitch_offset",))
    field = model.correction_field()
    fine = refined_grid(COARSE, np.array([-9.0, 26.0]), np.array([0.1, 1.0]))
    n = fine.n_lift
    rng = np.random.default_rng(7404)
    B = rng.standard_normal((7, 2 * n))
    prior_std = np.abs(rng.standard_normal(len(model.parameters))) + 0.5
    length = 1.3
    D = discrepancy_correlation(COARSE, fine, field.between_node_lengths(length))
    lay = field.layout
    var = [np.mean(prior_std[idx.ravel()] ** 2) for idx in (lay.lift_index, lay.drag_index)]
    dense = sum(var[b] * B[:, b * n:(b + 1) * n] @ D @ B[:, b * n:(b + 1) * n].T for b in (0, 1))
    fs = SimpleNamespace(fine=fine, n_fine=n)
    full = discrepancy_propagated(B, field, fs, prior_std, length)
    diag = discrepancy_propagated(B, field, fs, prior_std, length, diagonal=True)
    np.testing.assert_allclose(full, dense, rtol=1e-9, atol=1e-12 * np.abs(dense).max())
    np.testing.assert_allclose(diag, np.diag(dense), rtol=1e-9)
    assert np.all(diag > 0)
