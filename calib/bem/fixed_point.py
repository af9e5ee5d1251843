"""A batch's solve at a given inflow, and its repetition to a fixed point when the inflow reads the thrust.

The conditions stage of the effect chain (:func:`conditions_stage`) gives the inflow speed V
and pitch β of every point; the sections are then built, their roots found and the section
pass run (:mod:`calib.bem.sections`). A conditions effect that reads the rotor thrust (e.g.
wind-tunnel blockage) makes the inflow depend on the solution, (V, β) = C(T, p):
:meth:`BatchSolve.to_fixed_point` repeats the solve with the thrust of the previous one,
iterating T = T_bem(C(T)) per point by the secant method (a fixed-point step first), until
the inflow speed changes by less than :data:`FIXED_POINT_TOL` (relative) at every point, at
most :data:`FIXED_POINT_MAX_ITER` times (see :func:`calib.bem.solver.solve_bem`, Notes).

References
----------
S.A. Ning, Wind Energy 17 (2014) 1327-1345 (the solve at a given inflow).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib.bem import dual as dl
from calib.bem.chain import BoundChain
from calib.bem.point_status import check_inflow
from calib.bem.sections import build_sections, find_roots, section_pass
from calib.bem.stages import Inflow, PointContext

FIXED_POINT_TOL = 1e-12
"""Relative change of the inflow speed below which a thrust-dependent inflow has settled [-]."""

FIXED_POINT_MAX_ITER = 30
"""Most solves of a thrust-dependent inflow (the secant iteration takes about 5-7)."""


class BatchSolve:
    """One batch's solve at a given inflow, and its repetition to a fixed point when the inflow reads the thrust.

    Built by :func:`calib.bem.solver.solve_bem` before its conditions stage.

    Parameters
    ----------
    rotor : Rotor
    conditions : OperatingConditions
        The measured conditions of the batch.
    settings : BemSettings
    chain : BoundChain
        The effect chain at the batch's parameter values.
    polars : SectionPolars
    opts : dict
        Loss and induction switches of ``settings``, as the section equations take them.
    n_sec : int
        Azimuth sectors per point.
    interior : ndarray of bool, shape (n_stations,)
        Stations that carry load.
    rotor_data : RotorData
    thrust_weights : ndarray, shape (n_stations,)
        Station weights [m] of the rotor thrust per point (blade count and sector average
        included).
    """

    def __init__(self, rotor, conditions, settings, chain, polars, opts, n_sec, interior, rotor_data, thrust_weights):
        self.rotor, self.conditions, self.settings, self.chain = rotor, conditions, settings, chain
        self.polars, self.opts, self.n_sec, self.interior = polars, opts, n_sec, interior
        self.rotor_data, self.thrust_weights = rotor_data, thrust_weights

    def at(self, inflow: Inflow, bad, k: int):
        """Sections, roots and section values at ``inflow`` (duals over ``k`` columns when k > 0)."""
        sec = build_sections(self.rotor, self.conditions, self.settings, self.n_sec, self.rotor_data, self.interior,
                             inflow.wind_speed, inflow.pitch, bad)
        roots = find_roots(sec, self.chain, self.polars, self.settings, self.opts, self.rotor)
        return sec, roots, section_pass(sec, roots, self.chain, self.polars, self.opts, k)

    def to_fixed_point(self, pctx: PointContext, bad_pt, msgs, sensitivities: bool):
        """The conditions stage and the solve; repeated while the inflow reads the thrust.

        See :func:`calib.bem.solver.solve_bem`, Notes.

        Returns
        -------
        inflow, bad, msgs, sec, roots, values, unsettled
        """
        chain = self.chain
        k = chain.n_section_columns if sensitivities else 0
        if not chain.reads_thrust:
            inflow = conditions_stage(chain, pctx)
            bad, msgs = check_inflow(inflow, bad_pt, msgs)
            return (inflow, bad, msgs) + self.at(inflow, bad, k) + (np.zeros(bad.size, bool),)
        thrust, previous = np.zeros(bad_pt.size), None          # first pass: no thrust yet
        for iteration in range(FIXED_POINT_MAX_ITER + 1):
            inflow = conditions_stage(chain, replace(pctx, thrust=thrust))
            bad, point_msgs = check_inflow(inflow, bad_pt, msgs)
            sec, roots, values = self.at(inflow, bad, 0)
            solved = sum_per_point(dl.value(values.quantities["Np"]), roots, sec, self.thrust_weights)
            settled = conditions_stage(chain, replace(pctx, thrust=np.nan_to_num(solved)))
            with np.errstate(invalid="ignore"):
                change = np.abs(settled.wind_speed - inflow.wind_speed) / np.abs(inflow.wind_speed)
            unsettled = np.isfinite(solved) & ~bad & ~(change <= FIXED_POINT_TOL)
            if not unsettled.any() or iteration == FIXED_POINT_MAX_ITER:
                break
            thrust, previous = _next_thrust(thrust, solved, previous), (thrust, solved)
        if k:
            values = section_pass(sec, roots, chain, self.polars, self.opts, k)
        for kpt in np.flatnonzero(unsettled):
            point_msgs[kpt] = (f"BEM: the inflow of the effect chain did not settle in {FIXED_POINT_MAX_ITER} "
                               f"solves (relative change of the inflow speed above {FIXED_POINT_TOL:g})")
        return inflow, bad, point_msgs, sec, roots, values, unsettled


def _next_thrust(thrust, solved, previous) -> np.ndarray:
    """Next thrust iterate of T = T_bem(C(T)) per point: secant on T_bem(C(T)) − T after the
    first step (fixed-point steps where the secant is undefined)."""
    step = np.nan_to_num(solved)
    if previous is None:
        return step
    t0, s0 = previous
    f1, f0 = np.nan_to_num(solved) - thrust, np.nan_to_num(s0) - t0
    with np.errstate(all="ignore"):
        secant = thrust - f1 * (thrust - t0) / (f1 - f0)
    return np.where(np.isfinite(secant) & (f1 != f0), secant, step)


def conditions_stage(chain: BoundChain, pctx: PointContext, k: int = 0) -> Inflow:
    """The conditions stage: inflow speed [m/s] and pitch [deg] per point.

    Parameters
    ----------
    chain : BoundChain
        The effect chain; without a conditions effect the measured inflow is returned.
    pctx : PointContext
        The measured conditions (and, for an effect that reads it, the rotor thrust [N]).
    k : int
        Derivative columns: 0 gives plain arrays of shape (n_points,), k > 0 the chain's
        duals over ``k`` columns.

    Returns
    -------
    Inflow
    """
    inflow = Inflow(pctx.wind_speed, pctx.pitch)
    if not chain.has("conditions"):
        return inflow
    out = chain.run("conditions", inflow, pctx, k)
    if k:
        return out
    return Inflow(np.broadcast_to(dl.value(out.wind_speed), pctx.wind_speed.shape).astype(float),
                  np.broadcast_to(dl.value(out.pitch), pctx.pitch.shape).astype(float))


def sum_per_point(section_values, roots, sec, weights) -> np.ndarray:
    """Σ_sectors Σ_stations w_i Q per point, NaN where a section did not converge.

    Parameters
    ----------
    section_values : ndarray, shape (n_active,)
        A section quantity Q on the active sections (e.g. N' [N/m]).
    roots : Roots
        The root search's result (its ``converged`` flags).
    sec : Sections
        The active sections of the batch and their place in (n_points, n_sectors, n_stations).
    weights : ndarray, shape (n_stations,)
        Station weights (e.g. the thrust weights of :class:`BatchSolve` [m]).

    Returns
    -------
    ndarray, shape (n_points,)
    """
    full = np.zeros(int(np.prod(sec.shape)))
    full[sec.sel] = np.where(roots.converged, section_values, np.nan)
    return np.einsum("ksi,i->k", full.reshape(sec.shape), weights)
