"""The additive polar-correction field as a parametrization of the parameter vector.

Where :mod:`calib.corrections` holds the shape functions (hat functions on an (α, η)
node grid), this module knows how a parameter vector carries them: which entries are
lift and drag nodes (rebuilt from the parameters' ``kind``, ``alpha_deg`` and ``eta``),
the dense field basis ΔC(α, η) = B p, the eigenshapes ψ_i(α, η) of right singular
vectors (Bottasso, Cacciola & Iriarte 2014, §3), the bound C_D ≥ C_D,min at the nodes,
and the confidence bands of the corrected polars. The smooth-field prior (correlation of the
nodes, the field between them) is computed in :mod:`calib.parametrizations.field_prior`, the
bands in :mod:`calib.parametrizations.field_bands`.

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.parametrizations.field_bands import band_coverage, polar_bands
from calib.parametrizations.field_prior import between_node_lengths, se_correlation, spacing_lengths, unresolved_variance
from calib.types import Evaluation, Parameter, ParameterKind

FIELD_KINDS = (ParameterKind.LIFT_CORRECTION, ParameterKind.DRAG_CORRECTION)
DEFAULT_PRIOR_CORRELATION = 1.0
"""Correlation length of the smooth-field prior in node spacings (see
:meth:`CorrectionField.node_correlation`); ``CalibrationSettings.prior_correlation``."""


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
    nodes = [(i, q) for i, q in enumerate(parameters) if q.kind in FIELD_KINDS]
    if not nodes:
        empty = np.zeros((0, 0), int)
        return NodeLayout(None, empty, empty)
    node_alpha = np.round(np.array([q.alpha_deg for _, q in nodes], float), 9)    # each list read once
    node_eta = np.round(np.array([q.eta for _, q in nodes], float), 9)
    alphas, etas = np.unique(node_alpha), np.unique(node_eta)
    if alphas.size < 2 or etas.size < 2:
        empty = np.zeros((0, 0), int)
        return NodeLayout(None, empty, empty)
    lift = -np.ones((alphas.size, etas.size), int)
    drag = -np.ones_like(lift)
    at = np.array([i for i, _ in nodes])
    a = np.searchsorted(alphas, node_alpha)
    e = np.searchsorted(etas, node_eta)
    is_lift = np.array([q.kind == ParameterKind.LIFT_CORRECTION for _, q in nodes], bool)
    lift[a[is_lift], e[is_lift]] = at[is_lift]
    drag[a[~is_lift], e[~is_lift]] = at[~is_lift]
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


def drag_floor_values(cd0, cd_min: float | None) -> np.ndarray:
    """Least ΔC_D [-] the bound C_D ≥ ``cd_min`` allows where the nominal C_D is ``cd0`` [-]:
    min(C_D,min − C_D,0, 0), so the nominal polar always lies inside, as in
    :meth:`CorrectionField.lower_bounds`; ``-inf`` without a bound."""
    cd0 = np.asarray(cd0, float)
    if cd_min is None:
        return np.full(cd0.shape, -np.inf)
    return np.minimum(cd_min - cd0, 0.0)


def seen_from_extras(evaluation: Evaluation) -> tuple[np.ndarray, np.ndarray]:
    """(α [deg], η [-]) of the loaded stations of converged points, from an evaluation whose
    ``extras`` carry ``alpha_deg`` (n_points, n_stations) and ``eta`` (n_stations,); NaN α
    marks stations without load."""
    a = np.asarray(evaluation.extras["alpha_deg"], float)
    e = np.broadcast_to(np.asarray(evaluation.extras["eta"], float), a.shape)
    keep = evaluation.ok[:, None] & np.isfinite(a)
    return a[keep], e[keep]


@dataclass(frozen=True, eq=False)
class CorrectionField:
    """What the calibrator knows about a ΔC_L, ΔC_D field carried by a parameter vector.

    Parameters
    ----------
    parameters : sequence of Parameter
        The model's whole parameter list; the field is rebuilt from the entries of kind
        ``lift_correction`` / ``drag_correction``.
    nominal_coefficients : callable (alpha_deg, eta) -> (cl0, cd0), optional
        Nominal C_L, C_D [-] at (α [deg], η [-]) (broadcast shapes). Without it the
        C_D bound and the corrected polars are not available (the ΔC bands still are).
    seen_points : callable (Evaluation) -> (alpha_deg, eta), optional
        Flat arrays of the (α, η) points the converged operating points reach.
    """

    parameters: tuple
    nominal_coefficients: Callable | None = None
    seen_points: Callable | None = None

    def __post_init__(self):
        object.__setattr__(self, "parameters", tuple(self.parameters))
        object.__setattr__(self, "_layout", node_layout(self.parameters))

    @property
    def layout(self) -> NodeLayout:
        return self._layout

    @property
    def grid(self) -> CorrectionGrid | None:
        return self._layout.grid

    @property
    def n_params(self) -> int:
        return len(self.parameters)

    def basis(self, alpha_deg, eta, block: str) -> np.ndarray:
        """Dense B (n_points_flat, n_params) with ΔC_block(α, η) = B @ p."""
        return field_basis(self._layout, alpha_deg, eta, block, n_params=self.n_params)

    def eigenshapes(self, V: np.ndarray, alpha_deg, eta, modes=None):
        """Lift and drag eigenshapes (n_modes, n_eta, n_alpha); see :func:`eigenshapes`."""
        return eigenshapes(V, self._layout, alpha_deg, eta, modes)

    def lower_bounds(self, lower: np.ndarray, p0: np.ndarray, cd_min: float | None) -> np.ndarray:
        """Lower bounds with C_D,0 + ΔC_D ≥ ``cd_min`` [-] at every drag node.

        A node whose nominal C_D is already below ``cd_min`` keeps its nominal value as
        bound (the estimate may not make it worse), so the start stays feasible.
        """
        lower = np.array(lower, float)
        if cd_min is None or self.nominal_coefficients is None:
            return lower
        idx = [j for j, q in enumerate(self.parameters) if q.kind == ParameterKind.DRAG_CORRECTION]
        if not idx:
            return lower
        a = np.array([self.parameters[j].alpha_deg for j in idx])
        e = np.array([self.parameters[j].eta for j in idx])
        _, cd0 = self.nominal_coefficients(a, e)
        cd0 = np.asarray(cd0, float).reshape(-1)
        for k, j in enumerate(idx):
            lower[j] = min(max(lower[j], cd_min - cd0[k]), p0[j])
        return lower

    def seen(self, evaluation: Evaluation) -> tuple[np.ndarray, np.ndarray]:
        """(α [deg], η [-]) reached by the converged points (empty arrays if unknown)."""
        if self.seen_points is None:
            return np.zeros(0), np.zeros(0)
        a, e = self.seen_points(evaluation)
        return np.asarray(a, float).reshape(-1), np.asarray(e, float).reshape(-1)

    def node_correlation(self, length: float = DEFAULT_PRIOR_CORRELATION) -> np.ndarray:
        """Prior correlation matrix of the parameters under the smooth-field prior [-].

        Within each block (lift, drag) the node values are correlated as samples of a
        stationary field with the squared-exponential correlation

        .. math::  ρ(Δα, Δη) = exp(−Δα²/(2ℓ_α²) − Δη²/(2ℓ_η²)),

        ℓ_α = ``length`` × the mean α node spacing, ℓ_η = ``length`` × the mean η node spacing
        (Rasmussen & Williams 2006, §4.2). Lift and drag blocks are independent of each other;
        every other parameter is independent of all (identity rows). ``length = 0`` gives
        independent nodes (the identity).

        Parameters
        ----------
        length : float
            Correlation length in node spacings [-].

        Returns
        -------
        ndarray, shape (n_params, n_params)
        """
        R = np.eye(self.n_params)
        if self.grid is None or not length > 0:
            return R
        lengths = self.correlation_lengths(length)
        for idx in (self._layout.lift_index, self._layout.drag_index):
            ia, ie = np.nonzero(idx >= 0)
            j = idx[ia, ie]
            a, e = self.grid.alpha_nodes_deg[ia], self.grid.eta_nodes[ie]
            R[np.ix_(j, j)] = se_correlation(a[:, None] - a[None], e[:, None] - e[None], lengths)
        return R

    def correlation_lengths(self, length: float) -> tuple[float, float]:
        """ℓ_α [deg] and ℓ_η [-] of the smooth-field prior for ``length`` node spacings (the
        grid's mean spacings; :meth:`node_correlation`)."""
        return spacing_lengths(self.grid, length)

    def between_node_lengths(self, length: float) -> tuple[float, float]:
        """ℓ_α [deg] and ℓ_η [-] of the field between the nodes for ``prior_correlation`` = ``length``:
        physical, no shorter than ``length`` × :data:`calib.parametrizations.field_prior.REFERENCE_SPACING`
        (:func:`calib.parametrizations.field_prior.between_node_lengths`)."""
        return between_node_lengths(self.grid, length)

    def representation_variance(self, alpha_deg, eta, block: str, prior_std: np.ndarray,
                                correlation_length: float = DEFAULT_PRIOR_CORRELATION) -> np.ndarray:
        """Variance of the true field between the nodes that the hat functions cannot carry [-²].

        σ_p² of the smooth-field prior is the block's mean prior variance (``prior_std``); the
        variance, zero at the nodes and σ_p² far from every node, is
        :func:`calib.parametrizations.field_prior.unresolved_variance` (its equation and limits).

        Parameters
        ----------
        alpha_deg, eta : array_like, broadcastable
        block : {"lift", "drag"}
        prior_std : ndarray, shape (n_params,)
            Prior 1-σ of every parameter [parameter unit].
        correlation_length : float
            In node spacings [-] (see :meth:`node_correlation`).

        Returns
        -------
        ndarray, flat over the broadcast shape
        """
        kind = ParameterKind.LIFT_CORRECTION if block == "lift" else ParameterKind.DRAG_CORRECTION
        idx = [j for j, q in enumerate(self.parameters) if q.kind == kind]
        if not idx or self.grid is None:
            return np.zeros(np.broadcast(np.asarray(alpha_deg), np.asarray(eta)).size)
        var_node = float(np.mean(np.asarray(prior_std, float)[idx] ** 2))
        return unresolved_variance(self.grid, alpha_deg, eta, var_node, correlation_length)

    def bands(self, p_hat: np.ndarray, cov_p: np.ndarray, cov_frozen: np.ndarray | None = None,
              alpha_deg=None, eta=None, confidence: float = 0.95, prior_std: np.ndarray | None = None,
              correlation_length: float = DEFAULT_PRIOR_CORRELATION, cd_min: float | None = None) -> dict:
        """Corrected polars C = C₀ + ΔC(α, η; p̂) with two-sided confidence bands.

        The band of ΔC_D respects the bound C_D ≥ ``cd_min`` the estimate obeys: where the
        Gaussian band would reach below it, the band is the shortest interval of the Gaussian
        truncated there (:func:`calib.parametrizations.field_bands.bounded_interval`,
        :meth:`drag_floor`).

        Parameters
        ----------
        p_hat : ndarray, shape (n_params,)
        cov_p : ndarray, shape (n_params, n_params)
            Covariance of p̂ including the frozen directions' prior variance.
        cov_frozen : ndarray, shape (n_params, n_params), optional
            The frozen directions' part of ``cov_p``; gives ``d*_prior_fraction``, the share
            of the band's variance that comes from the prior, not the data.
        alpha_deg : array_like, shape (n_a,), optional
            Default: 121 points over the α node range.
        eta : array_like, shape (n_e,), optional
            Default: the η nodes.
        confidence : float
        prior_std : ndarray, shape (n_params,), optional
            With it, the representation variance (:meth:`representation_variance`) is added
            to the bands and counted as prior.
        correlation_length : float
            Of the smooth-field prior, in node spacings (:meth:`node_correlation`).
        cd_min : float, optional
            Lower bound on C_D [-] (``CalibrationSettings.cd_min``); ``None``: no bound.

        Returns
        -------
        dict
            ``alpha_deg`` (n_a,), ``eta`` (n_e,), ``confidence``; per block ``dcl``/``dcd``,
            ``dcl_lower``/``dcl_upper``, ``dcd_lower``/``dcd_upper`` (the band's ends, ΔC [-]),
            ``dcl_half_width``/``dcd_half_width`` (z·σ of the untruncated Gaussian),
            ``dcl_prior_fraction``/``dcd_prior_fraction`` (n_e, n_a); ``cl0``, ``cd0`` where
            nominal polars are known.
        """
        return polar_bands(self, p_hat, cov_p, cov_frozen, alpha_deg, eta, confidence, prior_std,
                           correlation_length, cd_min)

    def drag_floor(self, alpha_deg, eta, cd_min: float | None) -> np.ndarray:
        """Least ΔC_D [-] the bound C_D ≥ ``cd_min`` allows at (α [deg], η [-])
        (:func:`drag_floor_values`); ``-inf`` without a bound or without nominal polars."""
        a, e = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
        if cd_min is None or self.nominal_coefficients is None:
            return np.full(a.shape, -np.inf)
        _, cd0 = self.nominal_coefficients(a, e)
        return drag_floor_values(np.broadcast_to(np.asarray(cd0, float), a.shape), cd_min)

    def coverage(self, p_hat: np.ndarray, cov_p: np.ndarray, alpha_deg, eta, truth_dcl, truth_dcd,
                 confidence: float = 0.95, prior_std: np.ndarray | None = None,
                 correlation_length: float = DEFAULT_PRIOR_CORRELATION, cd_min: float | None = None) -> dict:
        """Fraction of points (α, η) where the band contains a known true correction (the
        bands of :meth:`bands`, the drag band bounded by ``cd_min``).

        Parameters
        ----------
        alpha_deg, eta : ndarray, shape (k,)
            Points [deg], [-] (e.g. those the operating points reach).
        truth_dcl, truth_dcd : ndarray, shape (k,)
            True ΔC_L, ΔC_D there [-].
        prior_std : ndarray, shape (n_params,), optional
            Adds the representation variance, as :meth:`bands` does.
        correlation_length : float
            Of the smooth-field prior, in node spacings (:meth:`node_correlation`).
        cd_min : float, optional
            Lower bound on C_D [-]; ``None``: no bound.

        Returns
        -------
        dict
            ``lift``, ``drag``: covered fraction [-]; ``n_points``.
        """
        return band_coverage(self, p_hat, cov_p, alpha_deg, eta, truth_dcl, truth_dcd, confidence, prior_std,
                             correlation_length, cd_min)
