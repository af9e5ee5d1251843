"""Annual energy production from a binned power curve (IEC 61400-12-1 formula).

Notes
-----
With bin centres V_i (i = 1..N), the power P_i in each bin and the cumulative distribution F of
the hub-height wind speed, IEC 61400-12-1 (ed. 2, §9.3) gives

.. math::
    AEP = N_h \\sum_{i=1}^{N} [F(V_i) - F(V_{i-1})] \\frac{P_{i-1} + P_i}{2},

with N_h = 8760 h, V_0 = V_1 − ΔV and P_0 = 0. The AEP is linear in the P_i: :func:`aep_weights`
returns the coefficients c_i so that AEP = c · P, which the uncertainty budget uses. The standard's
Rayleigh distribution of annual mean wind speed V̄ is F(V) = 1 − exp(−π/4 (V/V̄)²); a Weibull
of shape k and scale A is F(V) = 1 − exp(−(V/A)^k).
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError

__all__ = ["HOURS_PER_YEAR", "IEC_RAYLEIGH_MEANS", "aep", "aep_weights", "rayleigh_cdf", "weibull_cdf"]

HOURS_PER_YEAR = 8760.0
#: Annual mean wind speeds of the standard's AEP table [m/s].
IEC_RAYLEIGH_MEANS = (4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0)


def rayleigh_cdf(v, mean_wind_speed: float):
    """Rayleigh cumulative distribution of wind speed ``v`` [m/s] with annual mean ``mean_wind_speed`` [m/s]."""
    if not mean_wind_speed > 0:
        raise InputError(f"the Rayleigh mean wind speed must be > 0, got {mean_wind_speed!r}", "aep",
                         field="mean_wind_speed")
    v = np.asarray(v, float)
    return 1.0 - np.exp(-np.pi / 4 * (np.maximum(v, 0.0) / mean_wind_speed) ** 2)


def weibull_cdf(v, k: float, A: float):
    """Weibull cumulative distribution of wind speed ``v`` [m/s]: shape ``k`` [-] > 0, scale ``A`` [m/s] > 0."""
    if not k > 0:
        raise InputError(f"the Weibull shape k must be > 0, got {k!r}", "--weibull", field="weibull")
    if not A > 0:
        raise InputError(f"the Weibull scale A must be > 0 m/s, got {A!r}", "--weibull", field="weibull")
    v = np.asarray(v, float)
    return 1.0 - np.exp(-(np.maximum(v, 0.0) / A) ** k)


def aep_weights(wind_speed, cdf) -> np.ndarray:
    """Coefficients c_i [h] of the IEC formula, AEP [Wh] = c · P [W].

    Parameters
    ----------
    wind_speed : array_like, shape (n_bins,)
        Bin centres, increasing, evenly spaced [m/s].
    cdf : callable
        Cumulative distribution F(V) of the hub-height wind speed.
    """
    v = np.asarray(wind_speed, float)
    if v.size < 2 or np.any(np.diff(v) <= 0):
        raise InputError("the bins need at least two increasing wind speeds", "aep", field="wind_speed")
    dv = v[1] - v[0]
    F = cdf(np.concatenate([[v[0] - dv], v]))
    dF = np.diff(F)                                    # F(V_i) − F(V_{i−1}), i = 1..N
    c = 0.5 * dF.copy()                                 # P_i's share of bin i
    c[:-1] += 0.5 * dF[1:]                              # and of bin i+1 (as P_{i−1})
    return HOURS_PER_YEAR * c


def aep(wind_speed, power, cdf) -> float:
    """AEP [Wh] of a binned power curve [W] under the wind-speed distribution ``cdf`` (IEC 61400-12-1)."""
    return float(aep_weights(wind_speed, cdf) @ np.asarray(power, float))
