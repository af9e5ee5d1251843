"""The additive polar-correction field ΔC_L(α, η), ΔC_D(α, η).

Notes
-----
Following Bottasso, Cacciola & Iriarte (2014), the corrections are written on
tensor products of one-dimensional piecewise-linear "hat" functions:

.. math::
    ΔC_L(α, η) = \\sum_{i,j} N_i(α) H_j(η) p^L_{ij},\\qquad
    ΔC_D(α, η) = \\sum_{i,j} N_i(α) H_j(η) p^D_{ij}

with nodes α_i [deg] and η_j = r/R [-]. Inside the node range the hats form a
partition of unity and the field is bilinear in every cell. Outside it, the first
and last hats ramp linearly to zero over one node spacing, so the field is
continuous everywhere and vanishes far from the grid (the tables are left as they are
where no node is placed).

The parameter vector is ``p = [p^L; p^D]`` with ``p^L[i * n_eta + j]`` the lift node at
(α_i, η_j). Because the field is linear in ``p``, ∂ΔC/∂p is the shape-function value.

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line
models from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.errors import InputError
from calib.types import Parameter, ParameterKind


def _check_nodes(nodes, name: str) -> np.ndarray:
    a = np.asarray(nodes, dtype=float).reshape(-1)
    if a.size < 2:
        raise InputError(f"need at least 2 nodes, got {a.size}", "CorrectionGrid", field=name)
    if not np.all(np.isfinite(a)):
        raise InputError("nodes must be finite", "CorrectionGrid", field=name)
    if np.any(np.diff(a) <= 0):
        raise InputError("nodes must be strictly increasing", "CorrectionGrid", field=name)
    return a


#: Node counts up to which a point's cell is found by comparing it with every inner node (a few
#: passes over the points, faster than a binary search for the grids the calibrations use).
_FEW_NODES = 16


def _cells(x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The cell k of every point, clip(#{nodes <= x} - 1, 0, n - 2): the two hats that may be
    non-zero at x are k and k + 1 (NaN in the last cell, as a binary search puts it)."""
    n = nodes.size
    if n > _FEW_NODES:
        return np.clip(np.searchsorted(nodes, x, side="right") - 1, 0, n - 2)
    k = np.zeros(x.shape, np.intp)
    for node in nodes[1:-1]:
        k += x >= node
    nan = np.isnan(x)
    if nan.any():
        k[nan] = n - 2
    return k


def _hat_columns(x, nodes: np.ndarray):
    """:func:`hat_weights` by column: the cell k and the two hats' values and slopes there
    (w0, w1, s0, s1), each of the shape of ``x``."""
    x = np.asarray(x, dtype=float)
    shape, x = x.shape, x.reshape(-1)
    k = _cells(x, nodes)
    h = np.diff(nodes)[k]
    t = (x - nodes[k]) / h
    w0, w1 = 1.0 - t, t
    s0, s1 = -1.0 / h, 1.0 / h
    below = np.flatnonzero(x < nodes[0])
    if below.size:      # below the first node: the first hat ramps to zero over one spacing
        h0 = nodes[1] - nodes[0]
        tb = (nodes[0] - x[below]) / h0
        w0[below] = np.where(tb < 1.0, 1.0 - tb, 0.0)
        s0[below] = np.where(tb < 1.0, 1.0 / h0, 0.0)
        w1[below], s1[below] = 0.0, 0.0
    above = np.flatnonzero(x > nodes[-1])
    if above.size:      # above the last node: the last hat ramps to zero over one spacing
        hn = nodes[-1] - nodes[-2]
        ta = (x[above] - nodes[-1]) / hn
        w1[above] = np.where(ta < 1.0, 1.0 - ta, 0.0)
        s1[above] = np.where(ta < 1.0, -1.0 / hn, 0.0)
        w0[above], s0[above] = 0.0, 0.0
    return tuple(a.reshape(shape) for a in (k, w0, w1, s0, s1))


def hat_weights(x, nodes: np.ndarray):
    """Values and slopes of the 1-D hat functions at ``x``.

    Parameters
    ----------
    x : array_like
        Evaluation points (any shape), in the unit of ``nodes``.
    nodes : ndarray, shape (n_nodes,)
        Strictly increasing node locations.

    Returns
    -------
    index : ndarray of int, shape x.shape + (2,)
        The two node indices with (possibly) non-zero weight.
    weight : ndarray, shape x.shape + (2,)
        Hat values N_index(x) [-].
    slope : ndarray, shape x.shape + (2,)
        dN_index/dx [1/unit of x].
    """
    k, w0, w1, s0, s1 = _hat_columns(x, nodes)
    return np.stack([k, k + 1], axis=-1), np.stack([w0, w1], axis=-1), np.stack([s0, s1], axis=-1)


@dataclass(frozen=True, eq=False)
class CorrectionGrid:
    """Node grid of the correction field.

    Parameters
    ----------
    alpha_nodes_deg : array_like, shape (n_alpha,)
        Angle-of-attack nodes [deg], strictly increasing.
    eta_nodes : array_like, shape (n_eta,)
        Spanwise nodes η = r/R [-], strictly increasing.
    cl_scale, cd_scale : float
        Typical magnitude of a lift / drag correction [-] (SVD scaling, docs/theory.md, Estimation).
    cl_bound, cd_bound : float
        Symmetric bounds on each nodal correction [-].
    cd_floor : float
        Least corrected C_D anywhere [-] (default 0.001): the corrected drag is held at
        min(``cd_floor``, C_D,0) wherever the field would take it lower, at every section's
        angle of attack, inside and outside the node range (:meth:`floor_drag`). Node bounds
        keep C_D ≥ ``cd_min`` at the nodes only; between and beyond them a bilinear field
        over a polar whose drag bucket lies between nodes can reach C_D ≤ 0, where the BEM
        cannot evaluate.
    """

    alpha_nodes_deg: np.ndarray
    eta_nodes: np.ndarray
    cl_scale: float = 0.1
    cd_scale: float = 0.01
    cl_bound: float = 1.0
    cd_bound: float = 0.2
    cd_floor: float = 0.001

    def __post_init__(self):
        object.__setattr__(self, "alpha_nodes_deg", _check_nodes(self.alpha_nodes_deg, "alpha_nodes_deg"))
        object.__setattr__(self, "eta_nodes", _check_nodes(self.eta_nodes, "eta_nodes"))
        for name in ("cl_scale", "cd_scale", "cl_bound", "cd_bound", "cd_floor"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise InputError(f"must be a positive number, got {getattr(self, name)!r}",
                                 "CorrectionGrid", field=name)

    @property
    def n_alpha(self) -> int:
        return int(self.alpha_nodes_deg.size)

    @property
    def n_eta(self) -> int:
        return int(self.eta_nodes.size)

    @property
    def n_lift(self) -> int:
        """Number of lift (and of drag) nodal parameters."""
        return self.n_alpha * self.n_eta

    @property
    def n_params(self) -> int:
        return 2 * self.n_lift

    def node_index(self, i_alpha: int, j_eta: int) -> int:
        """Position of lift node (i_alpha, j_eta) in the lift block."""
        return i_alpha * self.n_eta + j_eta

    def basis(self, alpha_deg, eta):
        """Sparse tensor-product basis at points (α, η).

        Parameters
        ----------
        alpha_deg : array_like
            Angle of attack [deg].
        eta : array_like
            r/R [-], broadcastable with ``alpha_deg``.

        Returns
        -------
        index : ndarray of int, shape (..., 4)
            Lift-block node indices (add ``n_lift`` for the drag block).
        value : ndarray, shape (..., 4)
            N_i(α) H_j(η).
        dvalue_dalpha : ndarray, shape (..., 4)
            ∂/∂α of ``value`` [1/deg].
        """
        index, value, dvalue = self._corners(alpha_deg, eta)
        return np.stack(index, axis=-1), np.stack(value, axis=-1), np.stack(dvalue, axis=-1)

    def _corners(self, alpha_deg, eta):
        """:meth:`basis` as lists of the four corners of each point's cell, in the order of
        its last axis ((α_k, η_l), (α_k, η_l+1), (α_k+1, η_l), (α_k+1, η_l+1))."""
        alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
        ka, wa0, wa1, sa0, sa1 = _hat_columns(alpha_deg, self.alpha_nodes_deg)
        ke, we0, we1, _, _ = _hat_columns(eta, self.eta_nodes)
        row = ka * self.n_eta + ke
        index = [row, row + 1, row + self.n_eta, row + (self.n_eta + 1)]
        value = [wa0 * we0, wa0 * we1, wa1 * we0, wa1 * we1]
        dvalue = [sa0 * we0, sa0 * we1, sa1 * we0, sa1 * we1]
        return index, value, dvalue

    def evaluate(self, p, alpha_deg, eta):
        """ΔC_L, ΔC_D and their α-slopes at (α, η).

        Parameters
        ----------
        p : array_like, shape (n_params,)
            Nodal values ``[p^L; p^D]`` [-].
        alpha_deg, eta : array_like
            Angle of attack [deg] and r/R [-].

        Returns
        -------
        dcl, dcd : ndarray
            Corrections [-].
        dcl_dalpha, dcd_dalpha : ndarray
            Their slopes [1/deg].
        """
        p = np.asarray(p, dtype=float)
        if p.shape != (self.n_params,):
            raise InputError(f"expected {self.n_params} correction values, got shape {p.shape}",
                             "CorrectionGrid.evaluate", field="p")
        index, value, dvalue = self._corners(alpha_deg, eta)
        lift = [p[: self.n_lift][i] for i in index]
        drag = [p[self.n_lift:][i] for i in index]
        out = []
        for weights, nodal in ((value, lift), (value, drag), (dvalue, lift), (dvalue, drag)):
            total = weights[0] * nodal[0]
            for w, v in zip(weights[1:], nodal[1:]):     # summed in the corners' order
                total = total + w * v
            out.append(total)
        return tuple(out)

    def parameters(self) -> tuple[Parameter, ...]:
        """The nodal parameters, lift block then drag block, in ``p`` order."""
        out = []
        # each node coordinate formatted once, not once per parameter (the refined grids of the
        # aliasing term have ~2 000 nodes)
        alphas = [(float(a), f"{a:g}") for a in self.alpha_nodes_deg]
        etas = [(float(e), f"{e:g}") for e in self.eta_nodes]
        for kind, letter, scale, bound in ((ParameterKind.LIFT_CORRECTION, "L", self.cl_scale, self.cl_bound),
                                           (ParameterKind.DRAG_CORRECTION, "D", self.cd_scale, self.cd_bound)):
            for a, a_text in alphas:
                for e, e_text in etas:
                    out.append(Parameter(
                        name=f"dC{letter}[alpha={a_text},eta={e_text}]", nominal=0.0, lower=-bound,
                        upper=bound, scale=scale, unit="-", kind=kind, alpha_deg=a, eta=e,
                        description=f"additive C_{letter} correction at alpha={a_text} deg, eta={e_text}"))
        return tuple(out)

    def to_dict(self) -> dict:
        return {"alpha_nodes_deg": self.alpha_nodes_deg.tolist(), "eta_nodes": self.eta_nodes.tolist(),
                "cl_scale": self.cl_scale, "cd_scale": self.cd_scale,
                "cl_bound": self.cl_bound, "cd_bound": self.cd_bound, "cd_floor": self.cd_floor}
