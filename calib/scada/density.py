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


def air_density_sigma(temperature, pressure, temperature_sigma, pressure_sigma, relative_humidity=0.0,
                      humidity_sigma=0.0):
    """1-σ of the air density :func:`air_density` gives, from the 1-σ of its inputs (first-order
    propagation with sensitivity factors, as IEC 61400-12-1 combines the uncertainty components of
    the density in its Annex E).

    Parameters
    ----------
    temperature, pressure, relative_humidity : array_like
        T [K], B [Pa], φ [-], as :func:`air_density`.
    temperature_sigma : array_like
        1-σ of T [K] (a temperature difference: the same in °C).
    pressure_sigma : array_like
        1-σ of B [Pa].
    humidity_sigma : array_like
        1-σ of φ [-].

    Returns
    -------
    ndarray
        σ_ρ [kg/m^3].

    Notes
    -----
    With ρ = (B/R₀ − φ P_w(T) k)/T, k = 1/R₀ − 1/R_w, P_w' = 0.0631846 P_w (:func:`vapour_pressure`):

    ∂ρ/∂B = 1/(R₀ T),  ∂ρ/∂φ = −k P_w/T,  ∂ρ/∂T = −ρ/T − φ k P_w'/T,

    σ_ρ² = (∂ρ/∂T σ_T)² + (∂ρ/∂B σ_B)² + (∂ρ/∂φ σ_φ)² (independent sensors). For dry air at 288 K
    and 101 325 Pa a σ_T of 1 K gives 0.35 % of ρ, a σ_B of 300 Pa 0.30 %.

    References
    ----------
    IEC 61400-12-1:2017, Annex E (uncertainty of the air density from the temperature, pressure and
    humidity components, combined with their sensitivity factors); JCGM 100:2008 (GUM), §5.1.
    """
    t = np.asarray(temperature, float)
    b = np.asarray(pressure, float)
    phi = np.asarray(relative_humidity, float)
    k = 1.0 / R_DRY_AIR - 1.0 / R_WATER_VAPOUR
    pw = vapour_pressure(t)
    rho = air_density(t, b, phi)
    d_t = -rho / t - phi * k * 0.0631846 * pw / t
    d_b = 1.0 / (R_DRY_AIR * t)
    d_phi = -k * pw / t
    return np.sqrt((d_t * np.asarray(temperature_sigma, float)) ** 2 + (d_b * np.asarray(pressure_sigma, float)) ** 2
                   + (d_phi * np.asarray(humidity_sigma, float)) ** 2)


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
