"""Polars at the wrong Reynolds number: drag and C_L,max follow the sections' actual Re."""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.effects.base import Effect, attached_weight, stall_weight
from calib.errors import InputError
from calib.types import Parameter


class ReynoldsNumber(Effect):
    """Drag and lift near stall scaled with the sections' Reynolds number (polar stage).

    Parameters
    ----------
    reference_reynolds : float, optional
        Reynolds number at which the tables hold [-]. Default: each station's reference of
        the rotor (:func:`calib.bem.polar_grid.station_reynolds`: rated rotor speed, design
        tip-speed ratio), which needs an operating schedule.
    nominal : dict, optional
        Nominal values of ``reynolds_drag_exponent`` and ``reynolds_lift_loss``.

    Notes
    -----
    With the section's kinematic chord Reynolds number Re = c √(V_x² + V_y²)/ν
    (:class:`calib.bem.stages.SectionContext`) and x = ln(Re_ref / Re):

    .. math::
        C_D = C_{D,2D}\\,[1 + w_D(α)\\,((Re_{ref}/Re)^{n} − 1)],\\qquad
        C_L = C_{L,2D}\\,(1 − k\\,x\\,w_L(α))

    The drag of attached flow scales like skin friction, C_f ∝ Re^(−1/5) turbulent and
    Re^(−1/2) laminar (Schlichting), so n is typically 0.1…0.5; C_L,max grows with Re
    (Abbott & von Doenhoff), so k > 0 lowers lift near stall below the tables' Re and raises
    it above. w_D = 1 for |α| <= 20 deg falling to 0 at 40 deg, w_L rises from α_s − 8 deg to
    the station's stall angle and fades from 25 to 45 deg (as for erosion). At Re = Re_ref
    the polars are the tables'.

    Fingerprint: C_P(λ) curves measured at different wind speeds do not collapse (the
    non-dimensional BEM gives one curve): at equal λ, C_P lower at low wind speed (low Re)
    than at high wind speed.

    References
    ----------
    H. Schlichting, K. Gersten, Boundary-Layer Theory, 9th ed., Springer (2017), skin friction.
    I.H. Abbott, A.E. von Doenhoff, Theory of Wing Sections, Dover (1959), Re dependence of C_L,max.
    """

    name = "reynolds_number"
    stage = "polar"
    uses_flow = True
    fingerprint = ("C_P(lambda) curves at different wind speeds do not collapse; at equal lambda C_P lower at low "
                   "wind speed (low Reynolds number)")
    OPTIONS = {"reference_reynolds": None}
    PARAMETERS = (
        Parameter("reynolds_drag_exponent", 0.0, -0.5, 1.0, 0.1, "-", "effect",
                  description="exponent n of C_D ~ (Re_ref/Re)^n in attached flow", prior_std=0.2),
        Parameter("reynolds_lift_loss", 0.0, -0.5, 1.0, 0.05, "-", "effect",
                  description="relative C_L change near stall per unit ln(Re_ref/Re)", prior_std=0.1),
    )

    def reference(self, ctx):
        """Reference Reynolds number of each section [-]."""
        if self.options["reference_reynolds"] is not None:
            return float(self.options["reference_reynolds"])
        ref = ctx.rotor.reference_reynolds
        if ref is None:
            raise InputError("the rotor has no operating schedule to give the tables' Reynolds number; pass "
                             "make_effect('reynolds_number', reference_reynolds=...)", f"effect {self.name!r}",
                             field="reference_reynolds")
        return ref[ctx.station]

    def apply(self, theta, state, ctx):
        n, k = theta
        x = np.log(self.reference(ctx)) - dl.log(ctx.reynolds)
        a = state.alpha_deg
        alpha_stall = np.clip(ctx.rotor.features.alpha_stall_deg[ctx.station], 5.0, 20.0)
        w_d = attached_weight(a, 20.0, 40.0)
        w_l = stall_weight(a, alpha_stall)
        cd = state.cd * (1.0 + w_d * (dl.exp(n * x) - 1.0))
        cl = state.cl * (1.0 - k * x * w_l)
        return state.replace(cl=cl, cd=cd)
