"""Wind-speed scale: the rotor sees k times the measured wind speed (anemometry error)."""

from __future__ import annotations

from calib.effects.base import Effect
from calib.types import Parameter


class WindSpeedScale(Effect):
    """A factor on the measured wind speed (conditions stage): V → k V.

    Parameters
    ----------
    nominal : dict, optional
        ``{"wind_scale": value}`` [-].

    Notes
    -----
    .. math:: V' = k V

    An anemometer calibration error, a nacelle transfer function, or (approximately, with a
    constant factor) tunnel blockage. Output coefficients (C_P, C_T) stay referred to the
    measured V.

    Fingerprint: the whole power curve stretched along V; at given rotor speed and pitch the
    model's outputs at V match the measurements at V/k, with C_P ∝ k³ at fixed λ' = ΩR/(kV).
    """

    name = "wind_speed_scale"
    stage = "conditions"
    fingerprint = ("power curve stretched along the wind speed; C_P off by k^3 at equal effective tip-speed "
                   "ratio; like blockage but independent of the thrust")
    PARAMETERS = (Parameter("wind_scale", 1.0, 0.8, 1.2, 0.02, "-", "nuisance",
                            description="factor on the measured wind speed (anemometry, blockage)", prior_std=0.05),)

    def apply(self, theta, inflow, ctx):
        (scale,) = theta
        return inflow.replace(wind_speed=inflow.wind_speed * scale)
