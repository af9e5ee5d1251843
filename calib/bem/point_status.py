"""Status and message of each operating point of a BEM solve, and the section arrays they are judged on.

- :func:`check_conditions`, :func:`check_inflow`: invalid inputs, before and after the
  effect chain's conditions stage (``INVALID_INPUT``);
- :func:`section_fields`: the ``sections`` dict of :class:`~calib.bem.solver.BemResult`,
  in (n_points, n_sectors, n_stations) arrays;
- :func:`status_per_point`: per-section trouble flags (no root, C_D <= 0, reversed flow,
  |a| > :data:`INDUCTION_LIMIT`, several roots) turned into a status and a message per point.

Used by :func:`calib.bem.solver.solve_bem`, whose Notes give the reasons for each status.
"""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.bem.sections import RESIDUAL_TOL
from calib.bem.stages import Inflow
from calib.types import OperatingConditions, Status

INDUCTION_LIMIT = 2.0
"""Largest |a| accepted at a converged section [-] (see :func:`calib.bem.solver.solve_bem`, Notes)."""


def check_conditions(conditions: OperatingConditions):
    """Per-point validity of the operating conditions: (bad mask, messages)."""
    n = len(conditions)
    msgs = [""] * n
    bad = np.zeros(n, bool)
    checks = (("wind_speed", conditions.wind_speed, lambda v: v > 0, "wind speed must be > 0 m/s"),
              ("rotor_speed", conditions.rotor_speed, lambda v: v > 0,
               "rotor speed must be > 0 rpm (parked rotors are outside the steady BEM)"),
              ("pitch", conditions.pitch, lambda v: np.abs(v) <= 180, "pitch must lie in [-180, 180] deg"),
              ("air_density", conditions.air_density, lambda v: v > 0, "air density must be > 0 kg/m^3"),
              ("yaw", conditions.yaw, lambda v: np.abs(v) < 90, "yaw must lie in (-90, 90) deg"))
    for name, v, ok, text in checks:
        with np.errstate(invalid="ignore"):
            fail = ~np.isfinite(v) | ~ok(v)
        for k in np.flatnonzero(fail & ~bad):
            msgs[k] = f"invalid input: {name} = {v[k]!r}; {text}"
        bad |= fail
    return bad, msgs


def check_inflow(inflow: Inflow, bad_pt, msgs):
    """Points whose inflow after the conditions stage is unusable (speed not finite and > 0)."""
    msgs = list(msgs)
    with np.errstate(invalid="ignore"):
        bad = ~bad_pt & ~(np.isfinite(inflow.wind_speed) & (inflow.wind_speed > 0) & np.isfinite(inflow.pitch))
    for kpt in np.flatnonzero(bad):
        msgs[kpt] = (f"invalid input: the effect chain's conditions stage gives wind speed "
                     f"{inflow.wind_speed[kpt]!r} m/s and pitch {inflow.pitch[kpt]!r} deg; the wind speed must be > 0")
    return bad_pt | bad, msgs


def _scatter(sec, roots, v, fill=0.0, dtype=float):
    """Section values of the active sections in a (n_points, n_sectors, n_stations) array (NaN where not converged)."""
    out = np.full(int(np.prod(sec.shape)), fill, dtype=dtype)
    out[sec.sel] = np.where(roots.converged, v, np.nan) if dtype is float else v
    return out.reshape(sec.shape)


def section_fields(sec, roots, values) -> dict:
    """The ``sections`` dict of :class:`BemResult`."""
    eq = values.eq
    fields = {"phi": roots.phi, "alpha_deg": values.alpha_deg, "cl": values.cl, "cd": values.cd,
              "a": dl.value(eq["a"]), "ap": dl.value(eq["ap"]), "W": dl.value(values.W), "residual": roots.residual,
              "iterations": roots.iterations.astype(float), "n_roots": roots.n_roots.astype(float)}
    for name in ("Np", "Tp", "cn", "ct"):
        fields[name] = dl.value(values.quantities[name])
    return {k: _scatter(sec, roots, v) for k, v in fields.items()}


def _section_flags(sec, roots, values) -> dict:
    """Per-section trouble flags for :func:`_point_status`."""
    conv = roots.converged
    with np.errstate(invalid="ignore"):
        wild = conv & ~(np.abs(dl.value(values.eq["a"])) <= INDUCTION_LIMIT)
    return {"failed": _scatter(sec, roots, ~conv, False, bool),
            "negative_drag": _scatter(sec, roots, values.cd <= 0.0, False, bool),
            "reversed_flow": sec.reversed_flow, "wild_induction": _scatter(sec, roots, wild, False, bool),
            "multiple_roots": _scatter(sec, roots, roots.n_roots > 1, False, bool)}


def status_per_point(sec, roots, values, a_sections, bad, msgs: list, unsettled, eta):
    """Status and message per point, and the points with several roots, from the section results.

    Parameters
    ----------
    sec, roots, values
        Sections, roots and section values of the solve.
    a_sections : ndarray, shape (n_points, n_sectors, n_stations)
        Axial induction a [-] (``sections["a"]`` of :func:`section_fields`).
    bad : ndarray of bool, shape (n_points,)
        Points with invalid input.
    msgs : list of str
        Message per point so far.
    unsettled : ndarray of bool, shape (n_points,)
        Points whose thrust-dependent inflow did not settle (NOT_CONVERGED).
    eta : ndarray, shape (n_stations,)
        r/R of the stations [-], named in messages.

    Returns
    -------
    status : ndarray of int, shape (n_points,)
        :class:`calib.types.Status` per point.
    msgs : list of str
    multiple : ndarray of bool, shape (n_points,)
        Valid points with a section whose residual has several roots.
    n_multiple : ndarray of int, shape (n_points,)
        Number of such sections.
    """
    flags = _section_flags(sec, roots, values)
    status, msgs = _point_status(flags, a_sections, bad, msgs, eta)
    status[unsettled & (status == Status.CONVERGED)] = int(Status.NOT_CONVERGED)
    multiple = flags["multiple_roots"].any(axis=(1, 2)) & ~bad
    n_multiple = flags["multiple_roots"].sum(axis=(1, 2))
    return status, msgs, multiple, n_multiple


def _point_status(flags: dict, a_sections, bad_pt, msgs: list, eta):
    """Status and message per point from per-section flags (n_points, n_sectors, n_stations).

    ``flags``: ``failed`` (no converged root), ``negative_drag`` (C_D <= 0), ``reversed_flow``
    (V_x <= 0), ``wild_induction`` (|a| > INDUCTION_LIMIT), ``multiple_roots`` (several roots;
    a note only, the status is unchanged).
    """
    status = np.full(bad_pt.size, int(Status.CONVERGED))
    status[bad_pt] = int(Status.INVALID_INPUT)
    trouble = flags["failed"] | flags["negative_drag"] | flags["reversed_flow"] | flags["wild_induction"]
    for kpt in np.flatnonzero(~bad_pt & (trouble | flags["multiple_roots"]).any(axis=(1, 2))):
        parts = []
        nd = int(flags["negative_drag"][kpt].sum())
        if nd:
            status[kpt] = int(Status.INVALID_INPUT)
            parts.append(f"C_D <= 0 at {nd} section(s) (corrected polar; the BEM needs positive drag)")
        elif trouble[kpt].any():
            status[kpt] = int(Status.NOT_CONVERGED)
        nf = int(flags["failed"][kpt].sum())
        if nf:
            parts.append(f"{nf} section(s) without a converged root (no sign change of the residual "
                         f"in Ning's brackets or |R| > {RESIDUAL_TOL:g})")
        nr = int(flags["reversed_flow"][kpt].sum())
        if nr:
            parts.append(f"{nr} section(s) with reversed inflow (V_x <= 0)")
        wild = flags["wild_induction"][kpt]
        if wild.any():
            a = np.where(wild, a_sections[kpt], 0.0)
            s_, i_ = np.unravel_index(np.argmax(np.abs(a)), a.shape)
            parts.append(f"axial induction outside the physical range |a| <= {INDUCTION_LIMIT:g} at "
                         f"{int(wild.sum())} section(s), e.g. a = {a[s_, i_]:.3g} at r/R = {eta[i_]:.3f} "
                         f"(induced velocity above twice the wind speed: no steady momentum balance)")
        multi = flags["multiple_roots"][kpt]
        if multi.any():
            where = ", ".join(f"{e:.3f}" for e in eta[np.flatnonzero(multi.any(axis=0))])
            parts.append(f"note: {int(multi.sum())} section(s) with several roots of the residual in "
                         f"their bracket (r/R = {where}); the root of smallest |φ| (least stalled) is used")
        msgs[kpt] = "BEM: " + "; ".join(parts)
    return status, msgs


