"""Completing airfoil polars to the full circle, -180..180 deg.

:func:`extrapolate_viterna` extends a table measured (or computed) over a limited range
of angle of attack with the Viterna & Corrigan (1982) flat-plate model, the way
AirfoilPrep and CCBlade's ``airfoilprep.py`` do it. :func:`densify_full_circle` pads
full-circle tables that have too few rows (cylinder tables with 2 or 3 rows).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from calib.errors import InputError
from calib.rotor.polar import MIN_POLAR_POINTS, PolarTable

#: Lift reduction applied to the Viterna lift beyond 90 deg and on the negative side
#: (AirfoilPrep / CCBlade ``cl_adj``) [-].
LIFT_ADJUSTMENT = 0.7

#: Flat-plate drag at 90 deg for an infinite aspect ratio, used when neither ``cd_max``
#: nor ``aspect_ratio`` is given [-] (1.11 + 0.018 * 50 = 2.01, Viterna & Corrigan 1982).
FLAT_PLATE_CD_MAX = 2.0

# Pitching moment near +-180 deg, AirfoilPrep v2 fixed table [deg] -> [-].
_CM_TAIL_ALPHA = np.array([-180.0, -175.0, -170.0, -165.0, 165.0, 170.0, 175.0, 180.0])
_CM_TAIL_VALUE = np.array([0.0, 0.2, 0.4, 0.35, -0.4, -0.5, -0.25, 0.0])

# The matched Viterna model: ``vit(alpha_rad, cl_adj) -> (cl, cd)`` [-].
_ViternaModel = Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]]


def cd_max_from_aspect_ratio(aspect_ratio: float) -> float:
    """Drag coefficient at 90 deg from the blade aspect ratio.

    Parameters
    ----------
    aspect_ratio : float
        Blade aspect ratio (length over mean chord) [-], > 0.

    Returns
    -------
    float
        C_D,max [-] = 1.11 + 0.018 AR, with AR capped at 50 (Viterna & Corrigan 1982).
    """
    if not np.isfinite(aspect_ratio) or aspect_ratio <= 0:
        raise InputError(f"aspect ratio must be a positive number, got {aspect_ratio!r}",
                         field="aspect_ratio")
    return 1.11 + 0.018 * min(float(aspect_ratio), 50.0)


def _viterna(alpha_rad, cd_max, coef_a, coef_b, cl_adj):
    alpha_rad = np.maximum(alpha_rad, 1e-4)  # as CCBlade: avoid 1/sin(0)
    cl = cd_max / 2 * np.sin(2 * alpha_rad) + coef_a * np.cos(alpha_rad) ** 2 / np.sin(alpha_rad)
    cd = cd_max * np.sin(alpha_rad) ** 2 + coef_b * np.cos(alpha_rad)
    return cl * cl_adj, cd


def extrapolate_viterna(table: PolarTable, cd_max: float | None = None, aspect_ratio=None, *,
                        cd_min: float = 0.001, n_alpha: int = 15) -> PolarTable:
    """Extend a polar to -180..180 deg with the Viterna & Corrigan model.

    Tables that already cover the full circle are returned unchanged.

    Parameters
    ----------
    table : PolarTable
        Table over a limited range. Its last angle, alpha_high, must lie in (0, 90] deg
        and is taken as the (stalled) matching point; its first angle must lie in
        (-90, alpha_high).
    cd_max : float, optional
        Drag coefficient of the flat plate at 90 deg [-]. Raised to the table's
        largest C_D if that is larger (as in CCBlade).
    aspect_ratio : float, optional
        Blade aspect ratio [-]; used when ``cd_max`` is None:
        C_D,max = 1.11 + 0.018 AR. With neither, C_D,max = 2.0 (flat plate).
    cd_min : float, default 0.001
        Lower bound on the extrapolated drag [-].
    n_alpha : int, default 15
        Points per extrapolated segment (CCBlade ``nalpha``).

    Returns
    -------
    PolarTable
        alpha_deg from -180 to 180 [deg]; the original rows are kept verbatim.

    Notes
    -----
    With α_h the matching angle and (C_L,h, C_D,h) the table values there,

    .. math::
        A = (C_{L,h} - C_{D,max}\\sin α_h\\cos α_h)\\sin α_h / \\cos^2 α_h, \\quad
        B = (C_{D,h} - C_{D,max}\\sin^2 α_h)/\\cos α_h

        C_L = \\tfrac12 C_{D,max}\\sin 2α + A\\cos^2α/\\sinα, \\quad
        C_D = C_{D,max}\\sin^2α + B\\cosα

    for α_h ≤ α ≤ 90 deg. As in AirfoilPrep/CCBlade, the range 90..180-α_h is the
    model evaluated at 180-α with C_L scaled by -0.7; 180-α_h..180 has C_L falling
    linearly to 0 at 180 deg; the negative side mirrors this (C_L scaled by -0.7 on
    -90..-α_h, +0.7 on -180+α_h..-90, linear to 0 at -180), and the gap -α_h..α_low
    (if any) is bridged linearly. C_L and C_D are continuous at every junction and
    C_L(±180) = C_L(±90) = 0. The moment uses AirfoilPrep's C_M model (centre of
    pressure moving aft) and its fixed table near ±180 deg.

    References
    ----------
    L.A. Viterna, D.C. Janetzke, Theoretical and experimental power from large
    horizontal-axis wind turbines, NASA TM-82944 (1982); L.A. Viterna, R.D. Corrigan,
    Fixed pitch rotor performance of large horizontal axis wind turbines, NASA CP-2230
    (1982). C. Hansen, AirfoilPrep v2.02, NREL NWTC (2012); S.A. Ning, CCBlade
    ``airfoilprep.py`` (``Polar.extrapolate``), github.com/WISDEM/CCBlade.
    """
    if table.covers_full_circle:
        return table
    _check_matching_range(table)
    if cd_max is None:
        cd_max = FLAT_PLATE_CD_MAX if aspect_ratio is None else cd_max_from_aspect_ratio(aspect_ratio)
    cd_max = max(float(cd_max), float(np.max(table.cd)))
    coef_a, coef_b = _viterna_coefficients(table, cd_max)
    vit = lambda a, s: _viterna(a, cd_max, coef_a, coef_b, s)  # noqa: E731
    alpha_new, cl_new, cd_new = _full_circle(table, vit, cd_min, n_alpha)
    # drop points that collide with table rows after the degree round trip
    keep = np.concatenate([[True], np.diff(alpha_new) > 1e-9])
    cm_new = None
    if table.cm is not None:
        cm_new = _extrapolate_cm(table, alpha_new, cl_new, cd_new)
    return PolarTable(alpha_new[keep], cl_new[keep], cd_new[keep],
                      None if cm_new is None else cm_new[keep], table.reynolds,
                      source=f"{table.source} (Viterna extrapolation, cd_max={cd_max:.4g})")


def _check_matching_range(table: PolarTable) -> None:
    """Refuse a table :func:`extrapolate_viterna` cannot match.

    Parameters
    ----------
    table : PolarTable
        Its last angle, alpha_high, must lie in (0, 90] deg; its first above -90 deg.

    Raises
    ------
    InputError
        Naming the table's source and ``alpha``.
    """
    src = table.source
    alpha = table.alpha_deg
    a_high, a_low = float(alpha[-1]), float(alpha[0])
    if not 0.0 < a_high <= 90.0:
        raise InputError(f"Viterna extrapolation needs the last angle in (0, 90] deg, got {a_high:g} deg",
                         src, field="alpha")
    if a_low <= -90.0:
        raise InputError(f"Viterna extrapolation needs the first angle above -90 deg, got {a_low:g} deg",
                         src, field="alpha")


def _viterna_coefficients(table: PolarTable, cd_max: float) -> tuple[float, float]:
    """Viterna's A and B matching the model to the table's last row.

    Parameters
    ----------
    table : PolarTable
        The last row (α_h [deg], C_L,h, C_D,h [-]) is the matching point.
    cd_max : float
        Flat-plate drag coefficient at 90 deg [-].

    Returns
    -------
    coef_a, coef_b : float
        A and B of :func:`extrapolate_viterna`, Notes [-]; both 0 when α_h = 90 deg (the model
        reduces to the flat plate).

    References
    ----------
    L.A. Viterna, R.D. Corrigan, NASA CP-2230 (1982).
    """
    cl_h, cd_h = float(table.cl[-1]), float(table.cd[-1])
    ah = np.radians(float(table.alpha_deg[-1]))
    sa, ca = np.sin(ah), np.cos(ah)
    if ca < 1e-9:  # matching at 90 deg: the model reduces to the flat plate
        return 0.0, 0.0
    coef_a = (cl_h - cd_max * sa * ca) * sa / ca ** 2
    coef_b = (cd_h - cd_max * sa * sa) / ca
    return coef_a, coef_b


def _full_circle(table: PolarTable, vit: _ViternaModel, cd_min: float,
                 n_alpha: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The table with the extrapolated segments on both sides, -180..180 deg.

    Parameters
    ----------
    table : PolarTable
        The table over a limited range.
    vit : callable
        ``vit(alpha_rad, cl_adj) -> (cl, cd)``, the matched Viterna model.
    cd_min : float
        Lower bound on the extrapolated drag [-].
    n_alpha : int
        Points per extrapolated segment.

    Returns
    -------
    alpha_deg, cl, cd : ndarray
        Angle of attack [deg] from exactly -180 to 180, C_L and C_D [-]; the table's rows
        verbatim in between (rows that collide after the degree round trip not yet dropped).
    """
    a_hi, cl_hi, cd_hi = _segments_above(table, vit, n_alpha)
    a_lo, cl_lo, cd_lo = _segments_below(table, vit, n_alpha)
    alpha_new = np.concatenate([np.degrees(a_lo), table.alpha_deg, np.degrees(a_hi)])
    cl_new = np.concatenate([cl_lo, table.cl, cl_hi])
    cd_new = np.concatenate([np.maximum(cd_lo, cd_min), table.cd, np.maximum(cd_hi, cd_min)])
    alpha_new[0], alpha_new[-1] = -180.0, 180.0  # exact ends despite round-off
    return alpha_new, cl_new, cd_new


def _segments_above(table: PolarTable, vit: _ViternaModel,
                    n_alpha: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The extrapolation from the table's last angle alpha_high to 180 deg (that angle excluded).

    Parameters
    ----------
    table : PolarTable
    vit : callable
        ``vit(alpha_rad, cl_adj) -> (cl, cd)``, the matched Viterna model.
    n_alpha : int
        Points per segment.

    Returns
    -------
    alpha_rad, cl, cd : ndarray
        Angle of attack [rad], C_L and C_D [-] (drag not yet bounded below): the model on
        alpha_high..90 deg, the model at 180-α with C_L scaled by -0.7 on 90..180-alpha_high,
        C_L falling linearly to 0 at 180 deg (AirfoilPrep / CCBlade).
    """
    ah = np.radians(float(table.alpha_deg[-1]))
    cl_h = float(table.cl[-1])
    adj = LIFT_ADJUSTMENT
    pi = np.pi
    # alpha_high .. 90
    a1 = np.linspace(ah, pi / 2, n_alpha)[1:]
    cl1, cd1 = vit(a1, 1.0)
    # 90 .. 180 - alpha_high
    a2 = np.linspace(pi / 2, pi - ah, n_alpha)[1:]
    cl2, cd2 = vit(pi - a2, -adj)
    # 180 - alpha_high .. 180: linear lift to zero
    a3 = np.linspace(pi - ah, pi, n_alpha)[1:]
    _, cd3 = vit(pi - a3, 1.0)
    cl3 = (a3 - pi) / ah * cl_h * adj
    return np.concatenate([a1, a2, a3]), np.concatenate([cl1, cl2, cl3]), np.concatenate([cd1, cd2, cd3])


def _segments_below(table: PolarTable, vit: _ViternaModel,
                    n_alpha: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The extrapolation from -180 deg to the table's first angle alpha_low (that angle excluded).

    Parameters
    ----------
    table : PolarTable
    vit : callable
        ``vit(alpha_rad, cl_adj) -> (cl, cd)``, the matched Viterna model.
    n_alpha : int
        Points per segment.

    Returns
    -------
    alpha_rad, cl, cd : ndarray
        Angle of attack [rad], C_L and C_D [-] (drag not yet bounded below): C_L rising
        linearly from 0 at -180 deg, the model with C_L scaled by +0.7 on -180+alpha_high..-90
        and by -0.7 on -90..-alpha_high, and a linear bridge from -alpha_high to alpha_low
        (if any) (AirfoilPrep / CCBlade).
    """
    ah, al = np.radians(float(table.alpha_deg[-1])), np.radians(float(table.alpha_deg[0]))
    cl_h, cd_h = float(table.cl[-1]), float(table.cd[-1])
    cl_l, cd_l = float(table.cl[0]), float(table.cd[0])
    adj = LIFT_ADJUSTMENT
    pi = np.pi
    # -alpha_high .. alpha_low: linear bridge
    if al <= -ah:
        a4 = cl4 = cd4 = np.empty(0)
        a5_end = al
    else:
        a4 = np.linspace(-ah, al, n_alpha)[:-1]
        cl4 = -cl_h * adj + (a4 + ah) / (al + ah) * (cl_l + cl_h * adj)
        cd4 = cd_l + (a4 - al) / (-ah - al) * (cd_h - cd_l)
        a5_end = -ah
    # -90 .. -alpha_high (or alpha_low)
    a5 = np.linspace(-pi / 2, a5_end, n_alpha)[:-1]
    cl5, cd5 = vit(-a5, -adj)
    # -180 + alpha_high .. -90
    a6 = np.linspace(-pi + ah, -pi / 2, n_alpha)[:-1]
    cl6, cd6 = vit(a6 + pi, adj)
    # -180 .. -180 + alpha_high: linear lift from zero
    a7 = np.linspace(-pi, -pi + ah, n_alpha)[:-1]
    _, cd7 = vit(a7 + pi, 1.0)
    cl7 = (a7 + pi) / ah * cl_h * adj

    return np.concatenate([a7, a6, a5, a4]), np.concatenate([cl7, cl6, cl5, cl4]), np.concatenate([cd7, cd6, cd5, cd4])


def _extrapolate_cm(table: PolarTable, alpha_deg, cl, cd) -> np.ndarray:
    """Pitching moment outside the table range, AirfoilPrep v2 / CCBlade ``__getCM``."""
    a, tcl, tcm = table.alpha_deg, table.cl, table.cm
    cm0 = None
    for i in range(a.size - 1):
        if abs(a[i]) < 20.0 and tcl[i] <= 0 <= tcl[i + 1] and tcl[i + 1] != tcl[i]:
            p = -tcl[i] / (tcl[i + 1] - tcl[i])
            cm0 = tcm[i] + p * (tcm[i + 1] - tcm[i])
            break
    if cm0 is None:
        cm0 = float(np.interp(0.0, a, tcm))
    ah = np.radians(a[-1])
    denom = tcl[-1] * np.cos(ah) + table.cd[-1] * np.sin(ah)
    if abs(denom) < 1e-12 or abs(np.cos(ah)) < 1e-9:
        coef = 0.0
    else:
        xm = (-tcm[-1] + cm0) / denom
        coef = (xm - 0.25) / np.tan(ah - np.pi / 2)
    cm = np.empty_like(alpha_deg)
    inside = (alpha_deg >= a[0]) & (alpha_deg <= a[-1])
    cm[inside] = np.interp(alpha_deg[inside], a, tcm)
    mid = ~inside & (np.abs(alpha_deg) < 165.0)
    ar = np.radians(alpha_deg[mid])
    pos = ar > 0
    x = np.where(pos, coef * np.tan(ar - np.pi / 2) + 0.25, coef * np.tan(-ar - np.pi / 2) + 0.25)
    c, d = cl[mid], cd[mid]
    cm[mid] = np.where(pos, cm0 - x * (c * np.cos(ar) + d * np.sin(ar)),
                       -(cm0 - x * (-c * np.cos(-ar) + d * np.sin(-ar))))
    tail = ~inside & ~mid
    cm[tail] = np.interp(alpha_deg[tail], _CM_TAIL_ALPHA, _CM_TAIL_VALUE)
    return cm


def densify_full_circle(alpha_deg, cl, cd, cm=None, min_points: int = MIN_POLAR_POINTS):
    """Pad a full-circle table that has fewer than ``min_points`` rows.

    Cylinder tables in AeroDyn and windIO files often have 2 or 3 rows (e.g. -180, 0,
    180 deg with constant C_D). Midpoints are inserted by linear interpolation, so the
    linearly interpolated polar is unchanged.

    Parameters
    ----------
    alpha_deg, cl, cd, cm : array_like, shape (n,)
        Angle of attack [deg] and coefficients [-]; ``cm`` may be None.
    min_points : int
        Rows wanted.

    Returns
    -------
    tuple of ndarray
        ``(alpha_deg, cl, cd, cm)``, unchanged when there are enough rows, when the
        table does not span -180..180 deg, or when alpha is not increasing.
    """
    alpha = np.asarray(alpha_deg, dtype=float)
    cols = [np.asarray(c, dtype=float) for c in (cl, cd)] + ([] if cm is None else [np.asarray(cm, float)])
    if (alpha.size >= min_points or alpha.size < 2 or alpha[0] > -179.5 or alpha[-1] < 179.5
            or np.any(np.diff(alpha) <= 0)):
        return alpha, cols[0], cols[1], (None if cm is None else cols[2])
    while alpha.size < min_points:
        mids = 0.5 * (alpha[:-1] + alpha[1:])
        new = np.sort(np.concatenate([alpha, mids]))
        cols = [np.interp(new, alpha, c) for c in cols]
        alpha = new
    return alpha, cols[0], cols[1], (None if cm is None else cols[2])
