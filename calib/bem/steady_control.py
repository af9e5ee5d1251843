"""Steady operating schedule of a variable-speed, pitch-to-feather turbine.

Below rated the rotor tracks the design tip-speed ratio within its speed limits at
fine pitch; above rated it runs at maximum speed and pitches toward feather until the
aerodynamic power equals rated power (the classic region 2 / region 3 schedule of
Jonkman et al., NREL/TP-500-38060, §7).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.bem.polar_grid import SectionPolars
from calib.bem.solver import BemResult, BemSettings, solve_bem
from calib.errors import InputError
from calib.types import STANDARD_AIR_DENSITY, OperatingConditions
from calib.rotor.geometry import Rotor


@dataclass(frozen=True, eq=False)
class PowerCurve:
    """Steady power curve.

    Attributes
    ----------
    wind_speed [m/s], rotor_speed [rpm], pitch [deg] : ndarray, shape (n,)
    result : BemResult
        The BEM solution at the scheduled points (power [W], thrust [N], ..., status).
    """

    wind_speed: np.ndarray
    rotor_speed: np.ndarray
    pitch: np.ndarray
    result: BemResult


def steady_power_curve(rotor: Rotor, wind_speed, settings: BemSettings | None = None, air_density=STANDARD_AIR_DENSITY,
                       polars: SectionPolars | None = None, pitch_tol=1e-3) -> PowerCurve:
    """Power curve of ``rotor`` under its :class:`~calib.rotor.geometry.OperatingSchedule`.

    Parameters
    ----------
    rotor : Rotor
        Must carry a ``schedule``.
    wind_speed : array_like
        Hub-height wind speeds [m/s].
    settings : BemSettings, optional
    air_density : float
        [kg/m^3]
    pitch_tol : float
        Tolerance of the above-rated pitch [deg] (vectorized bisection).
    """
    if rotor.schedule is None:
        raise InputError("the rotor has no operating schedule; a power curve needs one", rotor.source,
                         field="schedule")
    sch = rotor.schedule
    polars = polars or SectionPolars.from_rotor(rotor)
    v = np.atleast_1d(np.asarray(wind_speed, float))
    rpm = np.clip(sch.design_tsr * v / rotor.rotor_radius * 30 / np.pi, sch.min_rotor_speed, sch.max_rotor_speed)
    pitch = np.full(v.shape, sch.fine_pitch)
    cond = OperatingConditions(v, rpm, pitch, air_density)
    res = solve_bem(rotor, cond, settings, polars=polars)
    above = np.flatnonzero(res.ok & (res.power > sch.rated_power))
    if above.size:
        lo = np.full(above.size, sch.fine_pitch)
        hi = np.full(above.size, 45.0)
        while np.max(hi - lo) > pitch_tol:
            mid = 0.5 * (lo + hi)
            r = solve_bem(rotor, OperatingConditions(v[above], rpm[above], mid, air_density), settings,
                          polars=polars)
            too_much = ~r.ok | (r.power > sch.rated_power)
            lo = np.where(too_much, mid, lo)
            hi = np.where(too_much, hi, mid)
        pitch[above] = 0.5 * (lo + hi)
        res = solve_bem(rotor, OperatingConditions(v, rpm, pitch, air_density), settings, polars=polars)
    return PowerCurve(v, rpm, pitch, res)


def cp_surface(rotor: Rotor, tsr, pitch, rotor_speed_rpm: float | None = None, settings=None,
               air_density=STANDARD_AIR_DENSITY, polars: SectionPolars | None = None):
    """C_P, C_T on a tip-speed-ratio × pitch grid.

    Parameters
    ----------
    tsr : array_like, shape (n_tsr,)
        Tip-speed ratios [-].
    pitch : array_like, shape (n_pitch,)
        Pitch angles [deg].
    rotor_speed_rpm : float, optional
        Rotor speed [rpm] (default: the schedule's maximum); the wind speed follows from λ.

    Returns
    -------
    cp, ct : ndarray, shape (n_pitch, n_tsr)
        NaN where the BEM failed.
    result : BemResult
    """
    tsr, pitch = np.asarray(tsr, float), np.asarray(pitch, float)
    if rotor_speed_rpm is None:
        if rotor.schedule is None:
            raise InputError("give rotor_speed_rpm (the rotor has no schedule)", rotor.source,
                             field="rotor_speed_rpm")
        rotor_speed_rpm = rotor.schedule.max_rotor_speed
    T, P = np.meshgrid(tsr, pitch)
    omega = rotor_speed_rpm * np.pi / 30
    cond = OperatingConditions(omega * rotor.rotor_radius / T.ravel(), np.full(T.size, rotor_speed_rpm),
                               P.ravel(), air_density)
    res = solve_bem(rotor, cond, settings, polars=polars)
    return res.cp.reshape(T.shape), res.ct.reshape(T.shape), res


__all__ = ["PowerCurve", "cp_surface", "steady_power_curve"]
