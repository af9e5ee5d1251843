"""Identifiability: Fisher matrix, Cramér–Rao bound, whitened SVD, eigenshapes, verdicts.

Notes
-----
With output noise v_k ~ N(0, R) and sensitivities G = ∂y/∂p stacked over the operating
points, the Fisher information is F = Gᵀ R⁻¹ G and the Cramér–Rao bound Cov(p̂) ≥ F⁻¹.
Parameters with different units are first scaled, p̃ = (p − p₀)/scale, and the SVD is
taken of the whitened, scaled sensitivities

.. math::  M = R^{-1/2} G D = U S V^T,\\qquad D = \\mathrm{diag}(scale),

so that the scaled Fisher matrix is F̃ = V S² Vᵀ. The new parameters θ = Vᵀ p̃ are
statistically independent with σ(θ_i) = 1/s_i. Those with σ(θ_i) <= σ̄ are retained;
the others are frozen at 0 (nominal). The *eigenshape* of θ_i is the correction pattern
it moves, ψ_i(α, η) = Σ_jl N_j(α) H_l(η) (v_i)_jl, for the lift and drag blocks
separately (Bottasso, Cacciola & Iriarte 2014, §3).

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import stats

from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.types import Parameter

VERDICTS = ("identified", "poorly observable", "at bound")


def whitened_sensitivities(G: np.ndarray, sigma: np.ndarray, scale: np.ndarray,
                           ok: np.ndarray | None = None) -> np.ndarray:
    """The whitened, scaled sensitivity matrix M = R^(−½) G D.

    Parameters
    ----------
    G : ndarray, shape (n_points, n_channels, n_params)
        ∂y/∂p [channel unit / parameter unit].
    sigma : ndarray, shape (n_points, n_channels)
        1-σ noise [channel unit] (diagonal R).
    scale : ndarray, shape (n_params,)
        Parameter scales [parameter unit].
    ok : ndarray of bool, shape (n_points,), optional
        Points to keep (converged ones); the others get zero rows.

    Returns
    -------
    ndarray, shape (n_points * n_channels, n_params)
        Rows point-major.
    """
    M = G * scale[None, None, :] / sigma[:, :, None]
    if ok is not None:
        M = np.where(ok[:, None, None], M, 0.0)
    M = np.nan_to_num(M, nan=0.0, posinf=0.0, neginf=0.0)
    return M.reshape(-1, G.shape[-1])


def fisher_matrix(M: np.ndarray) -> np.ndarray:
    """Scaled Fisher information F̃ = Mᵀ M, shape (n_params, n_params) [1/scale²]."""
    return M.T @ M


def cramer_rao(F: np.ndarray, rcond: float = 1e-12):
    """Cramér–Rao bound, standard deviations and correlation matrix.

    Parameters
    ----------
    F : ndarray, shape (n, n)
        Fisher matrix.
    rcond : float
        Relative cut-off of the pseudo-inverse; directions below it get infinite variance.

    Returns
    -------
    cov : ndarray, shape (n, n)
        F⁺ (pseudo-inverse; ``inf`` on the diagonal for unobservable parameters).
    std : ndarray, shape (n,)
    correlation : ndarray, shape (n, n)
        χ_pq = (F⁻¹)_pq / √((F⁻¹)_pp (F⁻¹)_qq); NaN for unobservable parameters.
    """
    w, V = np.linalg.eigh(0.5 * (F + F.T))
    wmax = max(float(w.max(initial=0.0)), 0.0)
    keep = w > rcond * wmax if wmax > 0 else np.zeros_like(w, bool)
    cov = (V[:, keep] / w[keep]) @ V[:, keep].T
    # a parameter touched by a null direction has unbounded variance
    null_weight = (V[:, ~keep] ** 2).sum(axis=1)
    var = np.diag(cov).copy()
    var[null_weight > 1e-8] = np.inf
    std = np.sqrt(var)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr[~np.isfinite(std), :] = np.nan
    corr[:, ~np.isfinite(std)] = np.nan
    cov = cov.copy()
    cov[np.diag_indices_from(cov)] = var
    return cov, std, corr


@dataclass(frozen=True, eq=False)
class SvdAnalysis:
    """SVD of the whitened, scaled sensitivities and the retained set.

    Attributes
    ----------
    singular_values : ndarray, shape (n_params,)
        s_i, descending (zero-padded when there are fewer rows than parameters) [1/scale].
    V : ndarray, shape (n_params, n_params)
        Right singular vectors as columns; θ = Vᵀ p̃.
    sigma_theta : ndarray, shape (n_params,)
        σ(θ_i) = 1/s_i [scale units] (inf for s_i = 0).
    sigma_bar : float
        Threshold: θ_i is retained when σ(θ_i) <= σ̄.
    retained : ndarray of bool, shape (n_params,)
    """

    singular_values: np.ndarray
    V: np.ndarray
    sigma_theta: np.ndarray
    sigma_bar: float
    retained: np.ndarray

    @property
    def n_retained(self) -> int:
        return int(self.retained.sum())

    @property
    def basis(self) -> np.ndarray:
        """V_ID, the retained columns, shape (n_params, n_retained)."""
        return self.V[:, self.retained]


def svd_analysis(M: np.ndarray, sigma_bar: float, max_retained: int | None = None) -> SvdAnalysis:
    """SVD of M and selection of the parameters with σ(θ_i) = 1/s_i <= σ̄.

    Parameters
    ----------
    M : ndarray, shape (m, n_params)
        Whitened, scaled sensitivities (:func:`whitened_sensitivities`).
    sigma_bar : float
        Largest acceptable standard deviation of a retained θ, in units of the
        parameter scales [-]. ``inf`` retains every direction with s_i > 0.
    max_retained : int, optional
        Cap on the number retained.
    """
    if not sigma_bar > 0:
        raise InputError(f"sigma_bar must be > 0, got {sigma_bar!r}", "svd_analysis", field="sigma_bar")
    n = M.shape[1]
    _, s, Vt = np.linalg.svd(M, full_matrices=True)
    s_full = np.zeros(n)
    s_full[: s.size] = s
    # deterministic sign: largest component of each vector positive
    V = Vt.T.copy()
    signs = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(n)])
    V *= np.where(signs == 0, 1.0, signs)
    tiny = 1e-12 * max(float(s_full[0]) if n else 0.0, 1e-300)
    with np.errstate(divide="ignore"):
        sig = np.where(s_full > tiny, 1.0 / np.where(s_full > tiny, s_full, 1.0), np.inf)
    retained = np.isfinite(sig) & (sig <= sigma_bar)
    if max_retained is not None and retained.sum() > max_retained:
        retained[np.flatnonzero(retained)[max_retained:]] = False
    return SvdAnalysis(s_full, V, sig, float(sigma_bar), retained)


def sigma_bar_for(smallest_correction: float, confidence: float = 0.95) -> float:
    """Threshold σ̄ from the smallest correction worth identifying.

    A θ_i is kept when a change of size ``smallest_correction`` (in scale units) is
    distinguishable from zero at the two-sided ``confidence`` level:
    σ̄ = smallest_correction / z_{(1+confidence)/2}.
    """
    return float(smallest_correction / stats.norm.ppf(0.5 * (1.0 + confidence)))


def subspace_cosines(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Cosines of the principal angles between the column spaces of orthonormal A and B."""
    if A.shape[1] == 0 or B.shape[1] == 0:
        return np.ones(0)
    return np.clip(np.linalg.svd(A.T @ B, compute_uv=False), 0.0, 1.0)


# ----------------------------------------------------------------------------- eigenshapes
@dataclass(frozen=True, eq=False)
class NodeLayout:
    """Where the correction nodes sit in the parameter vector.

    Attributes
    ----------
    grid : CorrectionGrid or None
        Node grid rebuilt from the parameters (``None`` if the model has no correction field).
    lift_index, drag_index : ndarray of int, shape (n_alpha, n_eta)
        Parameter index of each node (-1 where absent).
    """

    grid: CorrectionGrid | None
    lift_index: np.ndarray
    drag_index: np.ndarray

    @property
    def has_field(self) -> bool:
        return self.grid is not None


def node_layout(parameters: Sequence[Parameter]) -> NodeLayout:
    """Rebuild the (α, η) node grid from the parameters of kind lift/drag_correction."""
    nodes = [(i, q) for i, q in enumerate(parameters) if q.kind in ("lift_correction", "drag_correction")]
    if not nodes:
        empty = np.zeros((0, 0), int)
        return NodeLayout(None, empty, empty)
    alphas = np.unique(np.round([q.alpha_deg for _, q in nodes], 9))
    etas = np.unique(np.round([q.eta for _, q in nodes], 9))
    if alphas.size < 2 or etas.size < 2:
        empty = np.zeros((0, 0), int)
        return NodeLayout(None, empty, empty)
    lift = -np.ones((alphas.size, etas.size), int)
    drag = -np.ones_like(lift)
    for i, q in nodes:
        a = int(np.searchsorted(alphas, round(q.alpha_deg, 9)))
        e = int(np.searchsorted(etas, round(q.eta, 9)))
        (lift if q.kind == "lift_correction" else drag)[a, e] = i
    grid = CorrectionGrid(alphas, etas)
    return NodeLayout(grid, lift, drag)


def field_basis(layout: NodeLayout, alpha_deg, eta, block: str, n_params: int | None = None) -> np.ndarray:
    """Dense basis B with ΔC(α, η) = B @ p for one block.

    Parameters
    ----------
    alpha_deg, eta : array_like, broadcastable
        Evaluation points [deg], [-].
    block : {"lift", "drag"}
    n_params : int, optional
        Length of the parameter vector (default: the last node index + 1).

    Returns
    -------
    ndarray, shape (n_points_flat, n_params_total)
        Rows in C order of the broadcast (α, η) shape.
    """
    if not layout.has_field:
        raise InputError("the model has no correction-field parameters", "field_basis")
    idx_map = layout.lift_index if block == "lift" else layout.drag_index
    index, value, _ = layout.grid.basis(alpha_deg, eta)
    index = index.reshape(-1, 4)
    value = value.reshape(-1, 4)
    n_total = n_params or int(max(layout.lift_index.max(), layout.drag_index.max())) + 1
    flat_map = idx_map.reshape(-1)  # lift-block node index -> parameter index
    B = np.zeros((index.shape[0], n_total))
    rows = np.repeat(np.arange(index.shape[0]), 4)
    cols = flat_map[index.reshape(-1)]
    vals = value.reshape(-1)
    good = cols >= 0
    np.add.at(B, (rows[good], cols[good]), vals[good])
    return B


def eigenshapes(V: np.ndarray, layout: NodeLayout, alpha_deg, eta, modes=None):
    """Eigenshapes ψ_i(α, η) of the lift and drag blocks on a mesh.

    Parameters
    ----------
    V : ndarray, shape (n_params, n_modes_total)
        Right singular vectors (columns), in scaled parameters.
    layout : NodeLayout
    alpha_deg : array_like, shape (n_a,)
    eta : array_like, shape (n_e,)
    modes : sequence of int, optional
        Columns of V to map (default: all).

    Returns
    -------
    lift, drag : ndarray, shape (n_modes, n_e, n_a)
        ψ in units of the block's scale per unit θ_i (multiply by ``cl_scale`` or
        ``cd_scale`` for ΔC per unit θ).
    """
    alpha_deg = np.asarray(alpha_deg, float)
    eta = np.asarray(eta, float)
    A, E = np.meshgrid(alpha_deg, eta)
    Vm = V if modes is None else V[:, list(modes)]
    n_total = V.shape[0]
    out = []
    for block in ("lift", "drag"):
        B = field_basis(layout, A, E, block, n_params=n_total)
        out.append((B @ Vm).T.reshape(Vm.shape[1], eta.size, alpha_deg.size))
    return out[0], out[1]


def observability(V: np.ndarray, retained: np.ndarray) -> np.ndarray:
    """Fraction of each scaled parameter's direction inside the retained subspace [-].

    o_j = Σ_{i retained} V_ji² ∈ [0, 1]: 1 means the data determine p̃_j through the
    retained θ, 0 means p̃_j is frozen at nominal.
    """
    return (V[:, retained] ** 2).sum(axis=1)


def parameter_verdicts(parameters: Sequence[Parameter], p_hat: np.ndarray, lower: np.ndarray,
                       upper: np.ndarray, obs: np.ndarray, std: np.ndarray,
                       observability_threshold: float = 0.5, bound_tolerance: float = 1e-3) -> list[dict]:
    """A plain verdict per physical parameter.

    Rules
    -----
    - ``at bound``: the estimate is within ``bound_tolerance`` × scale of a bound.
    - ``identified``: observability o_j >= ``observability_threshold``.
    - ``poorly observable``: otherwise (the estimate stays close to nominal and is
      driven by the prior, not the data).

    Returns
    -------
    list of dict
        name, kind, verdict, value, nominal, std, observability, lower, upper.
    """
    out = []
    for j, q in enumerate(parameters):
        tol = bound_tolerance * q.scale
        if p_hat[j] <= lower[j] + tol or p_hat[j] >= upper[j] - tol:
            verdict = "at bound"
        elif obs[j] >= observability_threshold:
            verdict = "identified"
        else:
            verdict = "poorly observable"
        out.append({"name": q.name, "kind": q.kind, "verdict": verdict, "value": float(p_hat[j]),
                    "nominal": float(q.nominal), "std": float(std[j]), "observability": float(obs[j]),
                    "lower": float(lower[j]), "upper": float(upper[j]), "unit": q.unit})
    return out
