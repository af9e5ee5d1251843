"""Wind-tunnel blockage: the rotor sees a higher equivalent free-stream speed than the tunnel's."""

from __future__ import annotations

from calib.bem import dual as dl
from calib.effects.base import Effect
from calib.errors import InputError
from calib.types import Parameter


class WindTunnelBlockage(Effect):
    """Glauert's blockage correction from the rotor's C_T and the area ratio (conditions stage).

    Parameters
    ----------
    ct_limit : float
        Above this C_T Glauert's factor C_T/√(1 − C_T), singular at 1, is continued along its
        tangent (C¹) [-]. Default 0.8.
    area_ratio : float, optional
        A known area ratio β = A/C (the facility's cross-section stated): the correction is then
        applied at this value and the effect has no free parameter. Default None (β estimated).
    nominal : dict, optional
        ``{"blockage_area_ratio": β}``.

    Notes
    -----
    A rotor of swept area A in a closed test section of area C sees the free-stream speed V'
    of an unbounded flow that gives it the same thrust and induction; with the thrust
    coefficient on the tunnel speed V, C_T = T / (½ρAV²), and β = A/C:

    .. math::
        \\frac{V'}{V} = 1 + \\frac{β}{4}\\,\\frac{C_T}{\\sqrt{1 − C_T}}

    Glauert's correction for an airscrew, V'/V = 1 − τ₄β/(2√(1 + 2τ₄)) with τ₄ = T/(ρAV²),
    written for a wind turbine whose thrust acts downstream (τ₄ = −C_T/2); √(1 − C_T) is the
    far-wake speed ratio of momentum theory (Mikkelsen & Sørensen 2002 compare it with
    actuator-disc computations; Bahaj et al. 2007 apply the same momentum reasoning).
    For C_T > ``ct_limit`` the factor is continued linearly (C¹) where the momentum
    picture no longer holds. β < 0 (an open jet's opposite blockage) is allowed, so that
    β = 0 lies inside the bounds. Outputs (C_P, C_T) stay referred to the measured speed.

    The thrust is the model's own: the solver repeats the solve, iterating the thrust by the
    secant method per point, until V' settles to 1e-12 (:func:`calib.bem.solver.solve_bem`),
    and differentiates the fixed point exactly by the implicit function theorem. A model
    with this effect costs about 5-8 solves per evaluation (7 on the NREL 5-MW at β = 0.15).

    Fingerprint: the model under-predicts power and thrust by an amount that grows with the
    thrust (C_T): most at high λ below rated, least at high wind with pitched blades; like a
    wind-speed scale, but not uniform.

    References
    ----------
    H. Glauert, Wind tunnel interference on wings, bodies and airscrews, ARC R&M 1566 (1933).
    R. Mikkelsen, J.N. Sørensen, Modelling of wind tunnel blockage, Global Windpower
    Conference, Paris (2002).
    A.S. Bahaj, A.F. Molland, J.R. Chaplin, W.M.J. Batten, Power and thrust measurements of
    marine current turbines under various hydrodynamic flow conditions in a cavitation tunnel
    and a towing tank, Renewable Energy 32 (2007) 407-426.
    """

    name = "wind_tunnel_blockage"
    stage = "conditions"
    reads_thrust = True
    fingerprint = ("power and thrust under-predicted by an amount growing with the thrust coefficient; like a "
                   "wind-speed scale, but not uniform")
    OPTIONS = {"ct_limit": 0.8, "area_ratio": None}
    PARAMETERS = (Parameter("blockage_area_ratio", 0.0, -0.3, 0.6, 0.05, "-", "effect",
                            description="rotor swept area over tunnel cross-section (Glauert's blockage)",
                            prior_std=0.1),)

    def __init__(self, **options):
        ratio = options.get("area_ratio")
        if ratio is not None and (isinstance(ratio, bool) or not isinstance(ratio, (int, float))
                                  or not 0.0 < ratio < 1.0):
            raise InputError(f"must be the rotor's swept area over the test section's, in (0, 1), got {ratio!r}",
                             f"effect {self.name!r}", field="area_ratio")
        super().__init__(**options)

    def _parameters(self):
        """No free parameter when the area ratio is known (``area_ratio``)."""
        return () if self.options["area_ratio"] is not None else tuple(self.PARAMETERS)

    def glauert(self, ct):
        """C_T/√(1 − C_T), continued along its tangent above ``ct_limit`` [-] (array or Dual)."""
        lim = float(self.options["ct_limit"])
        value = lim / (1.0 - lim) ** 0.5
        slope = (1.0 - 0.5 * lim) / (1.0 - lim) ** 1.5
        below = dl.value(ct) <= lim
        safe = dl.where(below, ct, 0.0 * ct)
        return dl.where(below, safe / dl.sqrt(1.0 - safe), value + slope * (ct - lim))

    def apply(self, theta, inflow, ctx):
        known = self.options["area_ratio"]
        (beta,) = theta if known is None else (float(known),)
        v = inflow.wind_speed
        ct = ctx.thrust / (0.5 * ctx.air_density * ctx.swept_area * v * v)
        return inflow.replace(wind_speed=v * (1.0 + 0.25 * beta * self.glauert(ct)))
