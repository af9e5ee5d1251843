"""The one C_P(λ, β) surface grid shared by every benchmark (native BEM and CCBlade).

Kept free of ``calib`` imports (numpy only) so that ``ccblade_runner.py``, which runs
inside the separate ``.bench-venv``, can import it too.
"""

from __future__ import annotations

import numpy as np

TSR_RANGE = (2.0, 14.0, 50)        # λ from 2 to 14, 50 values
PITCH_RANGE_DEG = (-2.0, 20.0, 44)  # β from -2 to 20 deg, 44 values  -> 2200 points
ROTOR_SPEED_RPM = 12.1              # fixed rotor speed; wind speed V = Ω R / λ
RHO = 1.225                         # air density [kg/m^3]
MU = 1.81206e-5                     # dynamic viscosity [kg/(m s)] (CCBlade's default)


def surface_grid() -> tuple[np.ndarray, np.ndarray, float]:
    """The surface grid: ``(tsr, pitch_deg, rotor_speed_rpm)``.

    ``tsr`` (50,) and ``pitch_deg`` (44,) are the axes; the surface is their tensor
    product with ``indexing="ij"``, i.e. arrays of shape ``(tsr.size, pitch.size)``
    with ``cp[i, j]`` at ``tsr[i]``, ``pitch[j]``. The wind speed of a point is
    ``V = Ω R / λ`` with ``Ω`` from ``rotor_speed_rpm`` and ``R`` the rotor radius
    (tip radius times cos(precone)); air density :data:`RHO`.
    """
    tsr = np.linspace(*TSR_RANGE[:2], TSR_RANGE[2])
    pitch = np.linspace(*PITCH_RANGE_DEG[:2], PITCH_RANGE_DEG[2])
    return tsr, pitch, ROTOR_SPEED_RPM


def surface_points(tsr, pitch, rotor_speed_rpm, rotor_radius):
    """Flattened operating points of the grid (C order, ``indexing="ij"``).

    Returns ``(wind_speed, rotor_speed_rpm, pitch_deg)``, each of shape
    ``(tsr.size * pitch.size,)``.
    """
    tsr = np.asarray(tsr, dtype=float)
    pitch = np.asarray(pitch, dtype=float)
    lam, beta = np.meshgrid(tsr, pitch, indexing="ij")
    omega = rotor_speed_rpm * np.pi / 30.0
    wind = omega * rotor_radius / lam
    return wind.ravel(), np.full(lam.size, float(rotor_speed_rpm)), beta.ravel()
