"""The additive polar-correction field ΔC_L(α, η), ΔC_D(α, η) as an effect of the chain."""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.bem.stages import CompiledPolar, ProbeMap
from calib.corrections import CorrectionGrid
from calib.effects.base import Effect
from calib.errors import InputError


def floor_drag(cd, cd0, cd_floor: float):
    """The corrected drag held at or above min(``cd_floor``, C_D,0) [-] (plain arrays or duals).

    Parameters
    ----------
    cd : ndarray or Dual
        Corrected C_D [-].
    cd0 : ndarray or Dual
        C_D before the correction [-]: where it is already below ``cd_floor`` the floor is
        C_D,0 itself, so the uncorrected model is never changed.
    cd_floor : float
        [-]

    Returns
    -------
    ndarray or Dual
        ``cd`` where it is at or above the floor, else the floor (with the floor's
        derivative: none with respect to the correction).
    """
    floor = dl.where(dl.value(cd0) < cd_floor, cd0, cd_floor)
    return dl.where(dl.value(cd) >= dl.value(floor), cd, floor)


class CorrectionFieldEffect(Effect):
    """Additive corrections of C_L and C_D on hat functions of (α, η) (polar stage).

    One concept, three types: the nodes and hat functions are :class:`calib.corrections.CorrectionGrid`;
    this class applies the field inside the BEM; the calibrator's view of the same field (layout,
    eigenshapes, bounds, bands) is :class:`calib.parametrizations.correction_field.CorrectionField`.

    Parameters
    ----------
    grid : CorrectionGrid, optional
        The node grid; or the keyword options of :class:`calib.corrections.CorrectionGrid`
        (``alpha_nodes_deg``, ``eta_nodes``, ``cl_scale``, ``cd_scale``, ``cl_bound``, ``cd_bound``,
        ``cd_floor``).

    Notes
    -----
    .. math::
        C_L = C_{L} + Σ_{ij} N_i(α) H_j(η) p^L_{ij},\\qquad C_D = C_D + Σ_{ij} N_i(α) H_j(η) p^D_{ij}

    (Bottasso, Cacciola & Iriarte 2014; :mod:`calib.corrections`), with the corrected C_D held
    at or above min(``cd_floor``, C_D) at every section (a polar with C_D ≤ 0 cannot be
    evaluated; where the floor acts, the drag nodes have no effect on that section, and the
    exact derivatives say so). The field is added after
    every other polar effect of the chain (``order``), so that on a model with named effects
    it shows what they leave unexplained. Its many parameters each act on few sections: it
    seeds two probes (an additive C_L and C_D) instead of one derivative column per node and
    maps them on the nodes with the shape-function values (:meth:`probe_map`).

    Fingerprint: none of its own; it localizes in (α, η) what the data ask of the polars.

    References
    ----------
    C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
    from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
    """

    name = "correction_field"
    stage = "polar"
    order = 100
    n_probes = 2
    fingerprint = "none of its own: the (alpha, eta) pattern the data ask of the polars"
    OPTIONS = {"alpha_nodes_deg": None, "eta_nodes": None, "cl_scale": 0.1, "cd_scale": 0.01,
               "cl_bound": 1.0, "cd_bound": 0.2, "cd_floor": 0.001}

    def __init__(self, grid: CorrectionGrid | None = None, **options):
        if grid is not None:
            options = {**grid.to_dict(), **options}
        elif options.get("alpha_nodes_deg") is None or options.get("eta_nodes") is None:
            raise InputError("the correction field needs its nodes: grid=CorrectionGrid(...) or the options "
                             "alpha_nodes_deg and eta_nodes", f"effect {self.name!r}", field="alpha_nodes_deg")
        super().__init__(**options)
        o = self.options
        self.grid = grid if grid is not None else CorrectionGrid(o["alpha_nodes_deg"], o["eta_nodes"], o["cl_scale"],
                                                                 o["cd_scale"], o["cl_bound"], o["cd_bound"],
                                                                 o["cd_floor"])
        self.options = self.grid.to_dict()

    def _parameters(self):
        o = self.options
        return CorrectionGrid(o["alpha_nodes_deg"], o["eta_nodes"], o["cl_scale"], o["cd_scale"], o["cl_bound"],
                              o["cd_bound"], o["cd_floor"]).parameters()

    def apply(self, theta, state, ctx, probes=(0.0, 0.0)):
        p = np.asarray(theta, float)
        a = state.alpha_deg
        dcl, dcd, scl, scd = self.grid.evaluate(p, dl.value(a), ctx.eta)
        if isinstance(a, dl.Dual):
            dcl, dcd = dl.Dual(dcl, scl[:, None] * a.d), dl.Dual(dcd, scd[:, None] * a.d)
        cl, cd = state.cl + dcl, state.cd + dcd
        if isinstance(probes[0], dl.Dual):
            cl, cd = cl + probes[0], cd + probes[1]
        return state.replace(cl=cl, cd=floor_drag(cd, state.cd, self.grid.cd_floor))

    def compiled_polar(self, theta) -> CompiledPolar:
        """The field at nodal values ``theta`` as the compiled BEM kernel evaluates it (the same
        arithmetic as :meth:`apply` on plain values)."""
        p = np.asarray(theta, float)
        g = self.grid
        return CompiledPolar(g.alpha_nodes_deg, g.eta_nodes, p[:g.n_lift], p[g.n_lift:], g.cd_floor)

    def probe_map(self, theta, alpha_deg, ctx) -> ProbeMap:
        """Node weights at the sections' angles of attack: lift nodes on probe 0, drag nodes on probe 1."""
        index, value, _ = self.grid.basis(alpha_deg, ctx.eta)
        return ProbeMap(np.concatenate([index, index + self.grid.n_lift], axis=-1),
                        np.concatenate([value, value], axis=-1), np.array([0, 0, 0, 0, 1, 1, 1, 1]))
