"""Air density from temperature, pressure and humidity, and the density normalization of wind speed.

Both as IEC 61400-12-1 (power performance measurements of electricity producing wind turbines,
ed. 2, 2017) writes them in its data normalization for power curves.
"""

from __future__ import annotations

import numpy as np

#: gas constant of dry air [J/(kg K)] (IEC 61400-12-1)
R_DRY_AIR = 287.05
#: gas constant of water vapour [J/(kg K)] (IEC 61400-12-1)
R_WATER_VAPOUR = 461.5
#: reference air density [kg/m^3] (ISO standard atmosphere at sea level)
RHO_REFERENCE = 1.225


def vapour_pressure(temperature):
    """Vapour pressure of water as IEC 61400-12-1 approximates it.

    Parameters
    ----------
    temperature : array_like
        Absolute air temperature T [K].

    Returns
    -------
    ndarray
        P_w [Pa].

    Notes
    -----
    P_w = 0.0000205 exp(0.0631846 T), T in kelvin (IEC 61400-12-1:2017, data normalization);
    at 15 °C it gives 1654 Pa, against 1705 Pa from the Magnus formula.
    """
    return 2.05e-5 * np.exp(0.0631846 * np.asarray(temperature, float))


def air_density(temperature, pressure, relative_humidity=0.0):
    """Air density from the 10-minute means of temperature, pressure and relative humidity.

    Parameters
    ----------
    temperature : array_like
        Absolute air temperature T [K].
    pressure : array_like
        Air pressure B [Pa].
    relative_humidity : array_like
        Relative humidity φ [-] (0..1); 0 (dry air) where none is measured.

    Returns
    -------
    ndarray
        ρ [kg/m^3].

    Notes
    -----
    ρ = (1/T) (B/R₀ − φ P_w (1/R₀ − 1/R_w)), R₀ = 287.05 J/(kg K) (dry air), R_w = 461.5 J/(kg K)
    (water vapour), P_w from :func:`vapour_pressure`.

    References
    ----------
    IEC 61400-12-1:2017, Wind energy generation systems - Part 12-1: Power performance
    measurements of electricity producing wind turbines, data normalization (air density).
    """
    t = np.asarray(temperature, float)
    b = np.asarray(pressure, float)
    phi = np.asarray(relative_humidity, float)
    return (b / R_DRY_AIR - phi * vapour_pressure(t) * (1.0 / R_DRY_AIR - 1.0 / R_WATER_VAPOUR)) / t


def normalized_wind_speed(wind_speed, density, reference_density=RHO_REFERENCE):
    """Wind speed normalized to a reference density, for a pitch-regulated turbine.

    Parameters
    ----------
    wind_speed : array_like
        10-minute mean wind speed V [m/s].
    density : array_like
        10-minute air density ρ [kg/m^3].
    reference_density : float
        ρ₀ [kg/m^3] (the site mean or 1.225).

    Returns
    -------
    ndarray
        V_n = V (ρ/ρ₀)^(1/3) [m/s].

    References
    ----------
    IEC 61400-12-1:2017, data normalization (turbines with active power control).
    """
    return np.asarray(wind_speed, float) * (np.asarray(density, float) / reference_density) ** (1.0 / 3.0)
