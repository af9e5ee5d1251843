"""Rotational augmentation (stall delay) of the inboard blade: Snel, Du–Selig, Chaviaropoulos–Hansen."""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.effects.base import Effect, attached_weight
from calib.types import Parameter

LIFT_SLOPE_MIN = 1.0
"""Stations whose fitted lift slope is below this [1/rad] (cylinders) get no correction."""


class RotationalAugmentation(Effect):
    """Stall delay on the rotating blade (polar stage), with a free strength s.

    Parameters
    ----------
    variant : {"snel", "du_selig", "chaviaropoulos_hansen"}
        The radial factor f of the model (below). Default ``"snel"``.
    inviscid_lift : {"fit", "thin_airfoil"}
        C_L,inv = C_Lα,fit (α − α0) with the slope of the station polar's linear fit, or
        2π (α − α0) (thin-airfoil theory, Snel's original). Default ``"fit"``.
    alpha_full_deg, alpha_end_deg : float
        Full correction for |α| <= ``alpha_full_deg``, falling smoothly (C¹) to none at
        ``alpha_end_deg`` [deg] (AirfoilPrep's ``linear_25_45`` blending: 25 and 45 deg).
    nominal : dict, optional
        ``{"stall_delay_strength": s}``.

    Notes
    -----
    With x = c/r, the blending weight w(α) and the strength s (s = 1: the published model,
    s = 0: the 2-D polars):

    .. math::
        C_L = C_{L,2D} + s\\,f_L\\,w(α)\\,(C_{L,inv} − C_{L,2D}),\\qquad
        C_D = C_{D,2D} + s\\,g_D\\,w(α)\\,(C_{D,2D} − C_{D,0})

    - ``snel`` (Snel, Houwink & Bosschers 1994): f_L = 3 x², g_D = 0.
    - ``du_selig`` (Du & Selig 1998, constants a = b = d = 1 as in AirfoilPrep): with
      Λ = ΩR/√(V² + (ΩR)²) = λ/√(1 + λ²) and e = R/(Λ r),
      f_L = (1/2π)[1.6 x/0.1267 · (1 − x^e)/(1 + x^e) − 1],
      f_D = (1/2π)[1.6 x/0.1267 · (1 − x^{e/2})/(1 + x^{e/2}) − 1], both clipped at 0, and
      g_D = −f_D (drag falls).
    - ``chaviaropoulos_hansen`` (Chaviaropoulos & Hansen 2000): f_L = 2.2 x cos⁴θ_t (θ_t the
      local twist), and the same factor on drag, g_D = f_L (as summarized by Breton et al.).

    C_L,inv uses the zero-lift angle α0 and slope of a least-squares line through the
    station's polar on −4…4 deg; C_D,0 is C_D at α0 (:class:`calib.bem.stages.PolarFeatures`).
    Stations with a fitted slope below :data:`LIFT_SLOPE_MIN` (cylinders) are left as they are.
    s < 0 (earlier stall) is allowed so that s = 0 lies inside the bounds.

    Fingerprint: measured power and torque above the model at high wind / low λ (stalled
    inboard sections), high-λ points (attached flow) nearly unchanged; in the correction
    field, ΔC_L > 0 at high α on small η.

    References
    ----------
    H. Snel, R. Houwink, J. Bosschers, Sectional prediction of lift coefficients on rotating
    wind turbine blades in stall, ECN-C--93-052 (1994).
    Z. Du, M.S. Selig, A 3-D stall-delay model for horizontal axis wind turbine performance
    prediction, AIAA-98-0021 (1998).
    P.K. Chaviaropoulos, M.O.L. Hansen, Investigating three-dimensional and rotational effects
    on wind turbine blades by means of a quasi-3D Navier-Stokes solver, J. Fluids Eng. 122
    (2000) 330-336.
    J.P. Breton, F.N. Coton, G. Moe, A study on rotational effects and different stall delay
    models using a prescribed wake vortex scheme and NREL Phase VI experiment data, Wind
    Energy 11 (2008) 459-482.
    AirfoilPrep / WISDEM ``Polar.correction3D`` (NREL): linear-region fit and 25-45 deg blending.
    """

    name = "rotational_augmentation"
    stage = "polar"
    fingerprint = ("power/torque above the model at high wind / low tip-speed ratio (stalled root), high-lambda "
                   "points nearly unchanged; Delta C_L > 0 at high alpha on the inboard blade")
    OPTIONS = {"variant": "snel", "inviscid_lift": "fit", "alpha_full_deg": 25.0, "alpha_end_deg": 45.0}
    CHOICES = {"variant": ("snel", "du_selig", "chaviaropoulos_hansen"), "inviscid_lift": ("fit", "thin_airfoil")}
    PARAMETERS = (Parameter("stall_delay_strength", 0.0, -1.0, 3.0, 0.5, "-", "effect",
                            description="strength of the stall-delay model (1 = as published, 0 = 2-D polars)",
                            prior_std=1.0),)

    def __init__(self, **options):
        super().__init__(**options)
        self.options["alpha_full_deg"] = float(self.options["alpha_full_deg"])
        self.options["alpha_end_deg"] = float(self.options["alpha_end_deg"])
        self.uses_flow = self.options["variant"] == "du_selig"

    def factors(self, ctx):
        """Radial factors (f_L, g_D) [-] at the sections of ``ctx`` (arrays or Duals)."""
        x = ctx.chord / ctx.r
        variant = self.options["variant"]
        if variant == "snel":
            return 3.0 * x * x, 0.0
        if variant == "chaviaropoulos_hansen":
            f = 2.2 * x * np.cos(np.radians(ctx.twist_deg)) ** 4
            return f, f
        lam = ctx.tip_speed_ratio
        big_lambda = lam / dl.sqrt(1.0 + lam * lam)
        e = (ctx.rotor.tip_radius / ctx.r) / big_lambda
        log_x = np.log(x)

        def f(exponent):
            xe = dl.exp(exponent * log_x)
            v = (1.0 / (2.0 * np.pi)) * (1.6 * x / 0.1267 * (1.0 - xe) / (1.0 + xe) - 1.0)
            return dl.where(dl.value(v) > 0.0, v, 0.0 * v)
        return f(e), -1.0 * f(0.5 * e)

    def apply(self, theta, state, ctx):
        (s,) = theta
        feat = ctx.rotor.features
        st = ctx.station
        slope = feat.lift_slope[st] if self.options["inviscid_lift"] == "fit" else 2.0 * np.pi
        lifting = feat.lift_slope[st] > LIFT_SLOPE_MIN
        a = state.alpha_deg
        cl_inv = slope * (a - feat.alpha0_deg[st]) * (np.pi / 180.0)
        w = attached_weight(a, self.options["alpha_full_deg"], self.options["alpha_end_deg"]) * lifting
        f_l, g_d = self.factors(ctx)
        cl = state.cl + s * f_l * w * (cl_inv - state.cl)
        cd = state.cd
        if not (isinstance(g_d, float) and g_d == 0.0):
            cd = cd + s * g_d * w * (state.cd - feat.cd0[st])
        return state.replace(cl=cl, cd=cd)
