"""Every posterior draw's schedule: batched (:mod:`calib.powercurve.batch`) or one by one.

:func:`solve_draws` solves the schedule for each row of a matrix of parameter vectors. Batched, every
draw's steps of :meth:`calib.powercurve.schedule.VariableSpeed.solve` (λ search, region-2 bins,
region-3 pitch iterations) or the fixed and table schedules' single solve run for a block of draws in
one BEM solve each, with per-point parameters; each point follows exactly the steps it follows in
the per-draw path, which stays as the reference (``batched=False``).
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.powercurve.batch import batchable, batched_solver
from calib.powercurve.schedule import ScheduledCurve, scheduled_arrays
from calib.types import OperatingConditions

__all__ = ["BATCH_DRAWS", "QUANTITIES", "schedule_batch", "solve_draws"]

#: Posterior draws per batched block (a block of 100 draws × 45 bins is 4 500 BEM points per solve; larger blocks ran slower here).
BATCH_DRAWS = 100

#: Quantities summarized per bin.
QUANTITIES = ("power", "thrust", "cp", "ct", "rotor_speed", "pitch")


def schedule_batch(schedule, bsolve, n_draws, wind_speed, air_density, guess=None, pitch_hint=None) -> ScheduledCurve:
    """``schedule`` solved for ``n_draws`` parameter vectors at once: a :class:`ScheduledCurve` of arrays
    of shape (n_draws, n_bins) (``tsr_opt``: (n_draws,)); ``bsolve(draw, conditions)`` from
    :func:`calib.powercurve.batch.batched_solver`. ``pitch_hint`` = (pitch (n_draws, n_bins), dP/dβ (n_bins,))."""
    v = np.asarray(wind_speed, float)
    if getattr(schedule, "kind", "") == "variable_speed":
        return _variable_batch(schedule, bsolve, n_draws, v, air_density, guess, pitch_hint)
    rpm, pitch = schedule.setting(v)
    return _fixed_batch(bsolve, n_draws, v, rpm, pitch, air_density)


def _fixed_batch(bsolve, n_draws, v, rpm, pitch, air_density) -> ScheduledCurve:
    """A fixed or table schedule for ``n_draws`` draws in one batched solve."""
    D, n = int(n_draws), v.size
    draw = np.repeat(np.arange(D), n)
    res = bsolve(draw, OperatingConditions(np.tile(v, D), np.tile(rpm, D), np.tile(pitch, D), air_density))
    shape = (D, n)
    st = res.status.reshape(shape).copy()
    nan = lambda x: np.where(st != 0, np.nan, x.reshape(shape))  # noqa: E731
    return ScheduledCurve(np.broadcast_to(v, shape), np.broadcast_to(rpm, shape), np.broadcast_to(pitch, shape),
                          nan(res.power), nan(res.thrust), nan(res.cp), nan(res.ct), st, np.full(shape, 2),
                          np.full(D, np.nan), D * n)


def _optimal_tsr_batch(self, bsolve, n_draws, air_density) -> tuple[np.ndarray, int]:
    """:meth:`VariableSpeed.optimal_tsr` of ``n_draws`` parameter vectors in one batched solve: λ* per draw [-]
    (NaN where every point of a draw's search failed) and the number of BEM points."""
    lam = self.design_tsr * np.linspace(0.65, 1.35, 13)
    D, m = int(n_draws), lam.size
    omega = self.max_rotor_speed * np.pi / 30
    res = bsolve(np.repeat(np.arange(D), m),
                 OperatingConditions(np.tile(omega * self.rotor_radius / lam, D), np.full(D * m, self.max_rotor_speed),
                                     np.full(D * m, self.fine_pitch), air_density))
    cp = np.where(res.ok, res.cp, -np.inf).reshape(D, m)
    k = np.argmax(cp, axis=1)
    rows = np.arange(D)
    best = cp[rows, k]
    out = np.where(np.isfinite(best), lam[k], np.nan)
    inner = (k > 0) & (k < m - 1)
    kk = np.clip(k, 1, m - 2)
    y0, y1, y2 = cp[rows, kk - 1], cp[rows, kk], cp[rows, kk + 1]
    h = lam[1] - lam[0]
    curv = y0 - 2 * y1 + y2                      # 2 a h² of the parabola through the three
    fit = inner & np.isfinite(y0) & np.isfinite(y1) & np.isfinite(y2) & (curv < 0)
    with np.errstate(all="ignore"):
        vertex = lam[kk] - h * (y2 - y0) / (2 * curv)
    out = np.where(fit, np.clip(vertex, lam[kk - 1], lam[kk + 1]), out)
    return out, D * m

def _variable_batch(self, bsolve, n_draws, wind_speed, air_density, guess=None, pitch_hint=None) -> ScheduledCurve:
    """:meth:`VariableSpeed.solve` for ``n_draws`` parameter vectors at once: arrays of shape (n_draws, n_bins),
    ``tsr_opt`` of shape (n_draws,). ``bsolve(draw, conditions)`` solves every point at its draw's
    parameters (:func:`calib.powercurve.batch.batched_solver`); ``pitch_hint`` = (pitch, dP/dβ)
    with shapes (n_draws, n_bins) and (n_bins,). Each point follows the same steps as in :meth:`VariableSpeed.solve`."""
    v = np.asarray(wind_speed, float)
    D, n = int(n_draws), v.size
    n_points = 0
    if self.tsr_rule == "optimal":
        tsr, n_points = _optimal_tsr_batch(self, bsolve, D, air_density)
        tsr = np.where(np.isfinite(tsr), tsr, self.design_tsr)
    else:
        tsr = np.full(D, float(self.design_tsr))
    rpm = np.clip(tsr[:, None] * v[None, :] / self.rotor_radius * 30 / np.pi, self.min_rotor_speed,
                  self.max_rotor_speed).reshape(-1)
    vf = np.tile(v, D)
    draw = np.repeat(np.arange(D), n)
    pitch = np.full(D * n, float(self.fine_pitch))
    res = bsolve(draw, OperatingConditions(vf, rpm, pitch, air_density))
    n_points += D * n
    above, rated = np.flatnonzero(res.ok & (res.power > self.rated_power)), None
    if above.size:
        g = None if guess is None else np.interp(vf[above], guess.wind_speed, guess.pitch)
        slope = None
        if pitch_hint is not None and g is not None:
            hint_pitch = np.asarray(pitch_hint[0], float).reshape(-1)[above]
            slope = np.tile(np.asarray(pitch_hint[1], float), D)[above]
            g = np.where(np.isfinite(hint_pitch), hint_pitch, g)
        b, r, ok, m = self.pitch_to_rated(bsolve, draw[above], vf[above], rpm[above], air_density, g, slope,
                                           per_point=True)
        n_points += m
        rated = (b, r, ok)
    power, thrust, cp, ct, status, region = scheduled_arrays(res, pitch, above, rated)
    shape = (D, n)
    return ScheduledCurve(np.broadcast_to(v, shape), rpm.reshape(shape), pitch.reshape(shape), power.reshape(shape),
                          thrust.reshape(shape), cp.reshape(shape), ct.reshape(shape), status.reshape(shape),
                          region.reshape(shape), tsr, n_points)


def solve_draws(model, schedule, draws_p, p_hat, v, air_density, central, pitch_grad=None, dP_dpitch=None,
                batched=None, progress=None, name="result"):
    """The schedule of every draw (rows of ``draws_p``): per quantity an array (n_draws, n_bins) (NaN where a
    solve failed), the status (n_draws, n_bins), λ* per draw, the BEM points solved and a note on how.

    ``pitch_grad`` (n_bins, n_params) and ``dP_dpitch`` (n_bins,) from the delta method start each draw's
    region-3 pitch search at its linearized pitch. ``batched``: None (batched where the model allows,
    else one by one), False (one by one), True (batched or an :class:`InputError` naming ``name``).
    """
    n_draws = draws_p.shape[0]
    out = {q: np.full((n_draws, v.size), np.nan) for q in QUANTITIES}
    status = np.zeros((n_draws, v.size), int)
    tsr = np.full(n_draws, np.nan)
    n_pts = 0
    notes = []
    why = batchable(model) if batched is not False else "the per-draw loop was asked for (batched=False)"
    if why and batched:
        raise InputError(f"the draws cannot be batched: {why}", name, field="batched")
    if n_draws and not why and getattr(schedule, "kind", "") in ("variable_speed", "fixed_speed", "table"):
        # every draw's schedule in a few large solves, in blocks of draws (bounded memory)
        for start in range(0, n_draws, BATCH_DRAWS):
            block = draws_p[start:start + BATCH_DRAWS]
            hint = None
            if pitch_grad is not None:
                hint = (central.pitch[None, :] + (block - p_hat) @ pitch_grad.T, dP_dpitch)
            c = schedule_batch(schedule, batched_solver(model, block), block.shape[0], v, air_density,
                               guess=central, pitch_hint=hint)
            rows = slice(start, start + block.shape[0])
            for q in QUANTITIES:
                out[q][rows] = np.where(c.ok, getattr(c, q), np.nan)
            status[rows], tsr[rows], n_pts = c.status, c.tsr_opt, n_pts + c.n_points
            if progress is not None:
                progress(min(start + BATCH_DRAWS, n_draws), n_draws)
        notes.append(f"the {n_draws} draws were solved batched ({BATCH_DRAWS} draws per block, per-point "
                     "parameters in one BEM solve per schedule step)")
    else:
        if n_draws:
            notes.append(f"the draws were solved one by one: {why or 'the schedule has no batched solve'}")
        for d in range(n_draws):
            # the linearized pitch of this draw starts its region-3 search (the search iterates to tolerance)
            hint = None if pitch_grad is None else (central.pitch + pitch_grad @ (draws_p[d] - p_hat), dP_dpitch)
            c = schedule.solve(model.solve, draws_p[d], v, air_density, guess=central, pitch_hint=hint)
            for q in QUANTITIES:
                x = getattr(c, q)
                out[q][d] = np.where(c.ok, x, np.nan)
            status[d], tsr[d], n_pts = c.status, c.tsr_opt, n_pts + c.n_points
            if progress is not None and (d + 1) % 100 == 0:
                progress(d + 1, n_draws)
    return out, status, tsr, n_pts, notes
