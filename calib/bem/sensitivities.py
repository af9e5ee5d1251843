"""Exact derivatives of a batch's solve: the chain's section blocks and the conditions stage per point.

The section derivatives come from the implicit-function theorem at the root
(:func:`calib.bem.sections.eliminate_phi`); each effect of the polar, induction and loads
stages adds a :class:`~calib.bem.jacobian.Block` of columns (with its probe map when it seeds
probes instead of one column per parameter, :class:`calib.bem.stages.ProbeMap`). The
conditions stage acts on the whole point: the derivatives dV/dp, dβ/dp of the inflow speed
and pitch per point come from one dual pass of :func:`calib.bem.fixed_point.conditions_stage`.
When that stage reads the rotor thrust, the thrust T(V, β, p) of the BEM and the inflow
(V, β) = C(T, p) meet at a fixed point, whose derivative per point is

.. math::  dT/dp = (∂T/∂p + ∂T/∂V ∂V/∂p + ∂T/∂β ∂β/∂p)
                   / (1 − ∂T/∂V ∂V/∂T − ∂T/∂β ∂β/∂T)

(implicit function theorem), carried into dV/dp and dβ/dp.

References
----------
S.A. Ning, Wind Energy 17 (2014) 1327-1345 (derivatives at the root of the residual).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib.bem import dual as dl
from calib.bem.chain import BoundChain
from calib.bem.fixed_point import conditions_stage, sum_per_point
from calib.bem.jacobian import Block, SectionSensitivities, project
from calib.bem.sections import eliminate_phi
from calib.bem.stages import ProbeMap


def batch_sensitivities(chain: BoundChain, values, roots, sec, pctx, thrust_weights) -> SectionSensitivities:
    """Section derivatives (implicit function at the root) and the inflow's derivatives per point.

    Parameters
    ----------
    chain : BoundChain
        The effect chain at the batch's parameter values.
    values : SectionValues
        The section pass on duals over the chain's section columns.
    roots : Roots
    sec : Sections
    pctx : PointContext
        The measured conditions of the batch.
    thrust_weights : ndarray, shape (n_stations,)
        Station weights [m] of the rotor thrust per point (:class:`calib.bem.fixed_point.BatchSolve`).

    Returns
    -------
    SectionSensitivities
        With the fixed-point feedback in the inflow's derivatives when the conditions stage
        reads the thrust (module docstring).
    """
    columns = eliminate_phi(values, roots, sec)
    n_pts, n_par = sec.shape[0], chain.n_params
    blocks = []
    alpha_sites = None
    for entry in chain.entries:
        if entry.effect.stage == "conditions":
            continue
        pm = None
        if entry.probed:
            pm = _scatter_probe_map(entry.effect.probe_map(chain.theta(entry), values.alpha_deg, sec.ctx),
                                    roots, sec)
            if alpha_sites is None:
                alpha_sites = _scatter_sites(dl.value(values.alpha_deg), roots, sec)
        blocks.append(Block(entry.offset, entry.n_params, entry.column - 1, entry.n_columns, pm, entry.effect.name))
    # conditions stage on duals: columns of its parameters, then the thrust
    k_pt = chain.n_point_columns + int(chain.reads_thrust)
    V_p, B_p = np.zeros((n_pts, n_par)), np.zeros((n_pts, n_par))
    V_T = B_T = np.zeros(n_pts)
    if k_pt:
        thrust = None
        if chain.reads_thrust:
            t = sum_per_point(dl.value(values.quantities["Np"]), roots, sec, thrust_weights)
            thrust = dl.Dual.seed(np.nan_to_num(t), k_pt, chain.n_point_columns)
        inflow = conditions_stage(chain, replace(pctx, thrust=thrust), k_pt)
        dV, dB = (_point_derivative(x, n_pts, k_pt) for x in (inflow.wind_speed, inflow.pitch))
        for entry in chain.stage("conditions"):
            sl = slice(entry.offset, entry.offset + entry.n_params)
            V_p[:, sl] = dV[:, entry.column:entry.column + entry.n_params]
            B_p[:, sl] = dB[:, entry.column:entry.column + entry.n_params]
        if chain.reads_thrust:
            V_T, B_T = dV[:, -1], dB[:, -1]
    sens = SectionSensitivities(columns, B_p, V_p, tuple(blocks), n_par, alpha_sites)
    if chain.reads_thrust:
        # fixed point T = T_bem(C(T, p), p): implicit function per point
        dT_direct = project(sens, "Np", thrust_weights)
        Dw = np.einsum("ksic,i->kc", columns["Np"][..., :2], thrust_weights)
        with np.errstate(all="ignore"):
            dT = dT_direct / (1.0 - Dw[:, 1] * V_T - Dw[:, 0] * B_T)[:, None]
        sens = SectionSensitivities(columns, B_p + B_T[:, None] * dT, V_p + V_T[:, None] * dT, tuple(blocks), n_par,
                                    alpha_sites)
    return sens


def _point_derivative(x, n_pts: int, k: int) -> np.ndarray:
    """The (n_points, k) derivative array of a per-point value (zeros for a plain value)."""
    if isinstance(x, dl.Dual):
        return np.broadcast_to(x.d, (n_pts, k))
    return np.zeros((n_pts, k))


def _scatter_probe_map(pm: ProbeMap, roots, sec) -> ProbeMap:
    """A probe map of the active sections, placed in (n_points, n_sectors, n_stations, m) arrays."""
    size = int(np.prod(sec.shape))
    m = pm.index.shape[-1]
    index = np.zeros((size, m), int)
    weight = np.zeros((size, m))
    index[sec.sel] = np.where(roots.converged[:, None], pm.index, 0)
    weight[sec.sel] = np.where(roots.converged[:, None], pm.weight, 0.0)
    return ProbeMap(index.reshape(sec.shape + (m,)), weight.reshape(sec.shape + (m,)), np.asarray(pm.probe))


def _scatter_sites(alpha_deg: np.ndarray, roots, sec) -> np.ndarray:
    """The converged active sections' angle of attack [deg] in an (n_points, n_sectors, n_stations)
    array, NaN elsewhere."""
    out = np.full(int(np.prod(sec.shape)), np.nan)
    out[sec.sel] = np.where(roots.converged, alpha_deg, np.nan)
    return out.reshape(sec.shape)
