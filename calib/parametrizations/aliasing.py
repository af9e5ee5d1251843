r"""The field between the nodes, seen by the data: its aliasing into the retained θ.

Notes
-----
The hat functions carry a correction field only through its nodal values; a true field
also varies between the nodes and beyond the node range. Under the smooth-field prior
(a stationary Gaussian field of variance σ_p² per block and squared-exponential
correlation, :meth:`calib.parametrizations.CorrectionField.node_correlation`) that part,
δ(x) = f(x) − Σ_i N_i(x) f(x_i), is what the polar bands add as the *representation
variance*. The measurements see it too: the operating points' sections sit between the
nodes, so the data carry δ's signature W δ (W the whitened sensitivities of the outputs to
the correction at the sections), and the truncated least-squares estimate of the retained
θ takes it up as if it were nodal signal:

.. math::  δθ_{ID} = S_{ID}^{-2} V_{ID}^T M^T W δ,
           \qquad Cov(δθ_{ID}) = S_{ID}^{-2} V_{ID}^T M^T W\, Σ_δ\, W^T M V_{ID} S_{ID}^{-2},

(M = U S Vᵀ the whitened scaled sensitivities at the estimate). The noise-only
Cov(θ̂_ID) = S_ID⁻² misses this term; with a truth drawn from the prior on a fine grid
(``benchmarks/bench_coverage.py``, twin (d)) the retained θ were off by up to 40 σ of that
covariance against the truth's nodal values, and the bands covered 88 % of the reached
(α, η) points instead of 95 %.

W and Σ_δ are computed on a grid ``factor`` times finer than the calibration's (each
interval split in ``factor``, extended by the end intervals' fine steps over the (α, η)
range the operating points reach): the model's exact Jacobian with respect to the fine nodes, at the
fine-grid vector that reproduces the estimate, and the prior covariance of the fine nodal
values minus their coarse interpolant,

.. math::  Σ_δ = σ_p^2 (K_{ff} − T K_{cf} − K_{fc} T^T + T K_{cc} T^T)

(K the correlation between fine (f) and calibration (c) nodes, T the calibration hats at
the fine nodes; Rasmussen & Williams 2006, §2.2). The term is the prior average: for a
truth exactly in the span of the hat functions it is conservative.

References
----------
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press
(2006), §2.2 and §4.2.
M.C. Kennedy, A. O'Hagan, Bayesian calibration of computer models, J. R. Stat. Soc. B 63
(2001) 425-464 (model discrepancy in calibration).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.corrections import CorrectionGrid
from calib.parametrizations.field_prior import se_correlation

#: Each calibration interval is split in this many parts for the aliasing term.
REFINEMENT = 3


def refined_nodes(nodes: np.ndarray, factor: int, lo: float, hi: float, clip=(-np.inf, np.inf)) -> np.ndarray:
    """Nodes splitting every interval of ``nodes`` in ``factor`` parts, extended by the end
    intervals' fine steps down to ``lo`` and up to ``hi`` (within ``clip``)."""
    nodes = np.asarray(nodes, float)
    inner = np.concatenate([np.linspace(a, b, factor + 1)[:-1] for a, b in zip(nodes[:-1], nodes[1:])]
                           + [nodes[-1:]])
    # outside, the end hats ramp to zero over the end interval: steps of that interval / factor
    s0, s1 = (nodes[1] - nodes[0]) / factor, (nodes[-1] - nodes[-2]) / factor
    lo, hi = max(lo, clip[0]), min(hi, clip[1])
    below = nodes[0] - s0 * np.arange(int(np.ceil(max(0.0, nodes[0] - lo) / s0 - 1e-9)), 0, -1)
    above = nodes[-1] + s1 * np.arange(1, int(np.ceil(max(0.0, hi - nodes[-1]) / s1 - 1e-9)) + 1)
    out = np.concatenate([below, inner, above])
    return out[(out >= clip[0] - 1e-12) & (out <= clip[1] + 1e-12)]


def refined_grid(grid: CorrectionGrid, alpha_deg, eta, factor: int = REFINEMENT) -> CorrectionGrid:
    """A grid ``factor`` times finer than ``grid`` covering its nodes and the reached (α, η)."""
    alpha_deg, eta = np.asarray(alpha_deg, float), np.asarray(eta, float)
    a = refined_nodes(grid.alpha_nodes_deg, factor, float(np.nanmin(alpha_deg, initial=np.inf)),
                      float(np.nanmax(alpha_deg, initial=-np.inf)))
    e = refined_nodes(grid.eta_nodes, factor, float(np.nanmin(eta, initial=np.inf)),
                      float(np.nanmax(eta, initial=-np.inf)), clip=(0.0, 1.0))
    return CorrectionGrid(a, e, grid.cl_scale, grid.cd_scale, cl_bound=10.0, cd_bound=10.0)


def interpolation_matrix(coarse: CorrectionGrid, fine: CorrectionGrid) -> np.ndarray:
    """T (n_fine_nodes, n_coarse_nodes): the coarse hats at the fine nodes (one block)."""
    A, E = np.meshgrid(fine.alpha_nodes_deg, fine.eta_nodes, indexing="ij")
    index, value, _ = coarse.basis(A.ravel(), E.ravel())
    T = np.zeros((A.size, coarse.n_lift))
    np.add.at(T, (np.repeat(np.arange(A.size), 4), index.ravel()), value.ravel())
    return T


def grid_correlation(a: CorrectionGrid, b: CorrectionGrid, lengths: tuple[float, float]) -> np.ndarray:
    """Smooth-field prior correlation between the nodes of ``a`` and of ``b`` (one block,
    node order α-major as in the grids' layout) [-]: the squared exponential separates, so it is
    the Kronecker product of its α and η factors (one product per pair of nodes, no exponential)."""
    d_alpha = a.alpha_nodes_deg[:, None] - b.alpha_nodes_deg[None]
    d_eta = a.eta_nodes[:, None] - b.eta_nodes[None]
    return np.kron(se_correlation(d_alpha, 0.0, (lengths[0], 1.0)), se_correlation(0.0, d_eta, (1.0, lengths[1])))


def grid_correlation_factors(g: CorrectionGrid, lengths: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """(L_α, L_η), the square roots of the α and η factors of :func:`grid_correlation` (g, g), whose
    Kronecker product L_α ⊗ L_η is :func:`grid_correlation_sqrt` [-]."""

    def factor(x, length):
        w, Q = np.linalg.eigh(se_correlation(x[:, None] - x[None], 0.0, (length, 1.0)))
        return Q * np.sqrt(np.clip(w, 0.0, None))

    return factor(g.alpha_nodes_deg, lengths[0]), factor(g.eta_nodes, lengths[1])


def grid_correlation_sqrt(g: CorrectionGrid, lengths: tuple[float, float]) -> np.ndarray:
    """L with L Lᵀ = :func:`grid_correlation` (g, g): the squared-exponential correlation on a
    tensor grid is the Kronecker product of its α and η factors, so L = L_α ⊗ L_η from two small
    eigen-decompositions [-]."""
    return np.kron(*grid_correlation_factors(g, lengths))


def times_kron(X: np.ndarray, A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """X (A ⊗ B) without forming the Kronecker product, X's columns in the order of A ⊗ B's rows
    (α-major on a grid: (i, j) at i n_B + j): (n_A n_B)² products per row become n_A n_B (n_A + n_B)."""
    n_a, n_b = A.shape[0], B.shape[0]
    Y = np.matmul(X.reshape(-1, n_a, n_b), B)               # Σ_j X[i, j] B[j, l]
    return np.matmul(A.T, Y).reshape(X.shape[0], -1)         # Σ_i A[i, k] (...)[i, l]


def discrepancy_correlation(coarse: CorrectionGrid, fine: CorrectionGrid, lengths: tuple[float, float]) -> np.ndarray:
    """K_ff − T K_cf − K_fc Tᵀ + T K_cc Tᵀ: the correlation of the fine nodal values minus their
    coarse interpolant under the smooth-field prior (unit variance) [-]."""
    T = interpolation_matrix(coarse, fine)
    TK = T @ grid_correlation(fine, coarse, lengths).T
    D = grid_correlation(fine, fine, lengths) - TK - TK.T + T @ grid_correlation(coarse, coarse, lengths) @ T.T
    return 0.5 * (D + D.T)


@dataclass(frozen=True, eq=False)
class FineSensitivities:
    """The whitened sensitivities of the outputs to a correction field on a finer grid.

    Attributes
    ----------
    fine : CorrectionGrid
        The refined grid (:func:`refined_grid`).
    W : ndarray, shape (n_points * n_channels, 2 * n_fine)
        ∂(y/σ)/∂(fine nodal values), lift block then drag block, zero rows at the points
        that do not enter the fit [1/parameter unit].
    n_fine : int
        Nodes of one block of the fine grid.
    """

    fine: CorrectionGrid
    W: np.ndarray
    n_fine: int


def fine_sensitivities(model, p: np.ndarray, conditions, sigma: np.ndarray, channel_index, ok: np.ndarray,
                       alpha_deg, eta, factor: int = REFINEMENT) -> FineSensitivities:
    """W of :class:`FineSensitivities` at the fine-grid vector that reproduces the estimate ``p``.

    Parameters are those of :func:`aliasing_covariance`.
    """
    field = model.correction_field()
    coarse = field.grid
    fine = refined_grid(coarse, alpha_deg, eta, factor)
    # the fine nodal values interpolate the estimate's field, so the fine model's solve is the estimate's:
    # a model that kept that solve's section derivatives maps them on the fine nodes without solving again
    projected = getattr(model, "field_jacobian", None)
    projected = projected(fine, p, conditions) if projected is not None else None
    if projected is not None:
        ev, G = projected
        use = np.asarray(ok, bool) & ev.ok
        W = G[:, list(channel_index), :]                # a copy, divided and zeroed in place
        W /= sigma[:, :, None]
        W[~use] = 0.0
        return FineSensitivities(fine, W.reshape(-1, G.shape[2]), fine.n_lift)
    fmodel = model.with_grid(fine)
    flay, clay = fmodel.correction_field().layout, field.layout
    T = interpolation_matrix(coarse, fine)
    p_fine = np.array([q.nominal for q in fmodel.parameters], float)
    by_name = {q.name: j for j, q in enumerate(model.parameters)}
    field_cols = set(clay.lift_index.ravel()) | set(clay.drag_index.ravel())
    for j, q in enumerate(fmodel.parameters):
        if q.name in by_name and by_name[q.name] not in field_cols:
            p_fine[j] = p[by_name[q.name]]
    cols = []
    for f_idx, c_idx in ((flay.lift_index, clay.lift_index), (flay.drag_index, clay.drag_index)):
        p_fine[f_idx.ravel()] = T @ p[c_idx.ravel()]
        cols.append(f_idx.ravel())
    ev, G = fmodel.jacobian(p_fine, conditions)
    use = np.asarray(ok, bool) & ev.ok
    W = G[:, channel_index, :][..., np.concatenate(cols)] / sigma[:, :, None]     # the measured channels indexed once
    W = np.where(use[:, None, None], W, 0.0).reshape(-1, sum(c.size for c in cols))
    return FineSensitivities(fine, W, int(cols[0].size))


def aliasing_covariance(model, p: np.ndarray, conditions, sigma: np.ndarray, channel_index, ok: np.ndarray,
                        M: np.ndarray, V_retained: np.ndarray, s_retained: np.ndarray, prior_std: np.ndarray,
                        correlation_length: float, alpha_deg, eta,
                        factor: int = REFINEMENT, sensitivities: FineSensitivities | None = None
                        ) -> tuple[np.ndarray, float]:
    """Cov(δθ_ID) [scale units²] of the retained θ from the field between the nodes.

    Parameters
    ----------
    model : BemModel-like
        A model whose capabilities are ``correction_field`` and ``refinable`` (``with_grid(grid)``).
    p : ndarray, shape (n_params,)
        The estimate.
    conditions : OperatingConditions
    sigma : ndarray, shape (n_points, n_channels)
        1-σ noise of the measured channels [channel unit].
    channel_index : sequence of int
        The measured channels among the model's.
    ok : ndarray of bool, shape (n_points,)
        Points that enter the fit.
    M : ndarray, shape (n_points * n_channels, n_params)
        Whitened scaled sensitivities at ``p``.
    V_retained : ndarray, shape (n_params, k)
    s_retained : ndarray, shape (k,)
        Retained right singular vectors and singular values of ``M``.
    prior_std : ndarray, shape (n_params,)
        Prior 1-σ of each parameter [parameter unit]; the blocks' mean variances set σ_p².
    correlation_length : float
        Of the smooth-field prior, in node spacings.
    alpha_deg, eta : ndarray
        The (α, η) the operating points reach (the fine grid covers them).
    factor : int
        Refinement of the calibration grid.
    sensitivities : FineSensitivities, optional
        :func:`fine_sensitivities` already computed at ``p`` (else computed here).

    Returns
    -------
    cov : ndarray, shape (k, k)
    misfit : float
        The χ² the field between the nodes adds to the residuals of the truncated fit on
        average, tr(P⊥ W Σ_δ Wᵀ P⊥) with P⊥ = I − U_ID U_IDᵀ [-].
    """
    field = model.correction_field()
    k = V_retained.shape[1]
    if k == 0 or not correlation_length > 0:
        return np.zeros((k, k)), 0.0
    fs = sensitivities or fine_sensitivities(model, p, conditions, sigma, channel_index, ok, alpha_deg, eta, factor)
    W = fs.W
    B = (V_retained.T @ (M.T @ W)) / s_retained[:, None] ** 2
    U = (M @ V_retained) / s_retained                  # retained left singular vectors
    P_W = W - U @ (U.T @ W)                            # the part of W δ the fit leaves in the residuals
    return (discrepancy_propagated(B, field, fs, prior_std, correlation_length),
            float(np.sum(discrepancy_propagated(P_W, field, fs, prior_std, correlation_length, diagonal=True))))


def discrepancy_propagated(B: np.ndarray, field, fs: FineSensitivities, prior_std: np.ndarray,
                           correlation_length: float, diagonal: bool = False) -> np.ndarray:
    """Cov(B δ) of a linear map B of the field between the nodes on the fine grid, δ ~ N(0, Σ_δ)
    per block (lift, drag) with Σ_δ = σ_p² (K_ff − T K_cf − K_fc Tᵀ + T K_cc Tᵀ).

    Parameters
    ----------
    B : ndarray, shape (k, 2 * n_fine)
        E.g. an estimator's gain times ``fs.W``: how the fine-grid field enters its output.
    field : CorrectionField
        The calibration's field (grid, layout, correlation lengths).
    fs : FineSensitivities
    prior_std : ndarray, shape (n_params,)
        Prior 1-σ per parameter [parameter unit]; each block's mean variance sets its σ_p².
    correlation_length : float
        ``prior_correlation`` [-]; the lengths are the field's between the nodes, physical
        (:meth:`CorrectionField.between_node_lengths`): the term falls as the grid is refined.
    diagonal : bool
        Only the variances (shape (k,)), without forming the k × k matrix.

    Returns
    -------
    ndarray, shape (k, k) or (k,)
    """
    # Σ_δ/σ_p² = K_ff − T K_cf − K_fc Tᵀ + T K_cc Tᵀ is never formed: K_ff and K_fc are Kronecker products
    # of their α and η factors (:func:`grid_correlation`), so B K_ff costs k n_f (n_α + n_η) products
    # (:func:`times_kron`) instead of k n_f², and the interpolant's terms go through the n_c coarse nodes
    # (X = B T, Y = B K_fc): B Σ_δ Bᵀ/σ_p² = (B K_ff) Bᵀ − X Yᵀ − Y Xᵀ + X K_cc Xᵀ (equal to round-off).
    coarse, fine = field.grid, fs.fine
    lengths = field.between_node_lengths(correlation_length)
    T = interpolation_matrix(coarse, fine)
    n = T.shape[0]
    ff = _correlation_factors(fine, fine, lengths)
    fc = _correlation_factors(fine, coarse, lengths)
    K_cc = grid_correlation(coarse, coarse, lengths)
    k = B.shape[0]
    out = np.zeros(k) if diagonal else np.zeros((k, k))
    for block, c_idx in enumerate((field.layout.lift_index, field.layout.drag_index)):
        var = float(np.mean(np.asarray(prior_std, float)[c_idx.ravel()] ** 2))
        Bb = B[:, block * n:(block + 1) * n]
        BK, X, Y = times_kron(Bb, *ff), Bb @ T, times_kron(Bb, *fc)
        XK = X @ K_cc
        if diagonal:
            out += var * (np.sum(BK * Bb, axis=1) - 2.0 * np.sum(X * Y, axis=1) + np.sum(XK * X, axis=1))
        else:
            XY = X @ Y.T
            out += var * (BK @ Bb.T - XY - XY.T + XK @ X.T)
    return out if diagonal else 0.5 * (out + out.T)


def _correlation_factors(a: CorrectionGrid, b: CorrectionGrid, lengths: tuple[float, float]
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The α and η factors of :func:`grid_correlation` (a, b), whose Kronecker product it is [-]."""
    return (se_correlation(a.alpha_nodes_deg[:, None] - b.alpha_nodes_deg[None], 0.0, (lengths[0], 1.0)),
            se_correlation(0.0, a.eta_nodes[:, None] - b.eta_nodes[None], (1.0, lengths[1])))
