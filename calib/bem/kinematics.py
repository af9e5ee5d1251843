"""Blade curvature and local inflow velocities (precone, precurve, presweep, tilt, yaw, shear).

Notes
-----
The coordinate transformations follow CCBlade's conventions (Ning 2014; WISDEM CCBlade
documentation, "azimuth" and "blade-aligned" coordinate systems): with precone β_c,
out-of-plane precurve x_c and in-plane presweep y_c,

.. math::
    x_{az} = -r \\sin β_c + x_c \\cos β_c,\\quad z_{az} = r \\cos β_c + x_c \\sin β_c,
    \\quad y_{az} = y_c

and the local cone angle is the slope of the (x_az, z_az) curve. At azimuth ψ with
yaw γ, tilt Θ, power-law shear exponent α_s and hub height H:

.. math::
    V = U (1 + h/H)^{α_s},\\quad h = (y_{az}\\sin ψ + z_{az}\\cos ψ)\\cos Θ - x_{az}\\sin Θ

    V_x = V[(\\cos γ \\sin Θ \\cos ψ + \\sin γ \\sin ψ)\\sin c + \\cos γ \\cos Θ \\cos c]
          - Ω y_{az} \\sin c

    V_y = V(\\cos γ \\sin Θ \\sin ψ - \\sin γ \\cos ψ) + Ω z_{az}

References
----------
S.A. Ning, A simple solution method for the blade element momentum equations with
guaranteed convergence, Wind Energy 17 (2014) 1327-1345; CCBlade theory documentation.
"""

from __future__ import annotations

import numpy as np


def curvature(r, precurve, presweep, precone_rad):
    """Azimuthal-frame coordinates, local cone angle and path length of a blade.

    Parameters
    ----------
    r, precurve, presweep : ndarray, shape (n,)
        Radius [m], out-of-plane and in-plane offsets [m].
    precone_rad : float
        Precone [rad].

    Returns
    -------
    x_az, y_az, z_az : ndarray, shape (n,)
        [m]
    cone : ndarray, shape (n,)
        Local total cone angle [rad].
    s : ndarray, shape (n,)
        Path length along the blade from the first point [m].
    """
    sp, cp = np.sin(precone_rad), np.cos(precone_rad)
    x_az = -r * sp + precurve * cp
    z_az = r * cp + precurve * sp
    y_az = np.asarray(presweep, float)
    seg = np.arctan2(-np.diff(x_az), np.diff(z_az))
    cone = np.empty_like(r, dtype=float)
    cone[0], cone[-1] = seg[0], seg[-1]
    cone[1:-1] = 0.5 * (seg[1:] + seg[:-1])
    ds = np.sqrt(np.diff(precurve) ** 2 + np.diff(presweep) ** 2 + np.diff(r) ** 2)
    s = np.concatenate([[0.0], np.cumsum(ds)])
    return x_az, y_az, z_az, cone, s


def wind_components(x_az, y_az, z_az, cone, azimuth_rad, wind_speed, omega, yaw_rad, tilt_rad,
                    hub_height, shear_exponent):
    """Local velocities normal to (V_x) and in (V_y) the rotor plane.

    Parameters
    ----------
    x_az, y_az, z_az, cone : ndarray, shape (n_stations,)
        From :func:`curvature`.
    azimuth_rad : ndarray, shape (n_sectors,)
        Blade azimuth [rad], 0 = blade pointing up.
    wind_speed, omega, yaw_rad : ndarray, shape (n_points,)
        Hub-height wind speed [m/s], rotor speed [rad/s], yaw misalignment [rad].
    tilt_rad, hub_height, shear_exponent : float
        Shaft tilt [rad], hub height [m], power-law exponent [-].

    Returns
    -------
    vx, vy : ndarray, shape (n_points, n_sectors, n_stations)
        [m/s]
    vx_wind, vy_wind : ndarray, same shape
        The wind parts of vx, vy (proportional to the wind speed) [m/s].
    """
    U = np.asarray(wind_speed, float)[:, None, None]
    Om = np.asarray(omega, float)[:, None, None]
    yaw = np.asarray(yaw_rad, float)[:, None, None]
    sy, cy = np.sin(yaw), np.cos(yaw)
    st, ct = np.sin(tilt_rad), np.cos(tilt_rad)
    psi = np.asarray(azimuth_rad, float)[None, :, None]
    sa, ca = np.sin(psi), np.cos(psi)
    sc, cc = np.sin(cone)[None, None, :], np.cos(cone)[None, None, :]
    xa, ya, za = (np.asarray(v, float)[None, None, :] for v in (x_az, y_az, z_az))
    if shear_exponent != 0.0:
        height = (ya * sa + za * ca) * ct - xa * st
        V = U * (1.0 + height / hub_height) ** shear_exponent
    else:
        V = U * np.ones_like(sa * xa)
    vx_wind = V * ((cy * st * ca + sy * sa) * sc + cy * ct * cc)
    vy_wind = V * (cy * st * sa - sy * ca)
    vx = vx_wind - Om * ya * sc
    vy = vy_wind + Om * za
    return vx, vy, vx_wind, vy_wind
