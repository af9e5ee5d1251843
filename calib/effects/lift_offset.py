"""A uniform lift shift of the polars in attached flow (a stall angle left in place)."""

from __future__ import annotations

import numpy as np

from calib.effects.base import Effect, smoothstep
from calib.types import Parameter


class LiftOffset(Effect):
    """ΔC_L added to every section's lift in attached flow, faded out through stall (polar stage).

    Parameters
    ----------
    fade_deg : float
        Width over which the shift fades out above the station's stall angle [deg]. Default 8.
    nominal : dict, optional
        ``{"lift_offset": value}`` [-].

    Notes
    -----
    With the station's stall angle α_s (maximum of its C_L on 0…30 deg, clipped to 5…20 deg):

    .. math::
        C_L = C_{L,2D} + ΔC_L\\,\\bigl(1 − S((α − α_s)/Δα_f)\\bigr)\\,\\bigl(1 − S((−α − 10°)/Δα_f)\\bigr)

    (S the C¹ smoothstep on [0, 1]): the same ΔC_L at every station and angle of the attached
    polar, nothing in separated flow. This is what tables measured at another Reynolds number,
    turbulence level or surface finish, or a camber or trailing-edge deviation of the built
    blade, do to the lift curve below stall to first order (Abbott & von Doenhoff 1959, ch. 7:
    a shift of the zero-lift angle at an unchanged lift slope).

    Fingerprint: in attached flow it is the same as a collective pitch offset (Δβ moves every
    α by −Δβ, i.e. ΔC_L ≈ −C_Lα Δβ at every station); the two separate only when the data
    reach stall, where a pitch offset moves the stall onset along β and a lift shift does not.

    References
    ----------
    I.H. Abbott, A.E. von Doenhoff, Theory of Wing Sections, Dover (1959).
    """

    name = "lift_offset"
    stage = "polar"
    fingerprint = ("same as a pitch offset in attached flow (uniform Delta C_L); leaves the stall onset in place, "
                   "where a pitch offset moves it")
    OPTIONS = {"fade_deg": 8.0}
    PARAMETERS = (Parameter("lift_offset", 0.0, -0.4, 0.4, 0.02, "-", "effect",
                            description="uniform C_L shift of the attached polar", prior_std=0.1),)

    def apply(self, theta, state, ctx):
        (shift,) = theta
        a = state.alpha_deg
        alpha_stall = np.clip(ctx.rotor.features.alpha_stall_deg[ctx.station], 5.0, 20.0)
        fade = float(self.options["fade_deg"])
        w = (1.0 - smoothstep((a - alpha_stall) / fade)) * (1.0 - smoothstep((-a - 10.0) / fade))
        return state.replace(cl=state.cl + shift * w)
