"""A stronger tip loss than Prandtl's: Shen et al.'s correction of the blade-element forces."""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.effects.base import Effect
from calib.types import Parameter


class TipLoss(Effect):
    """Shen's tip correction F1 on the blade-element forces, raised to a free strength (induction stage).

    Parameters
    ----------
    c1, c2, c3 : float
        Constants of g (Shen et al. 2005: 0.125, 21, 0.1).
    nominal : dict, optional
        ``{"tip_loss_strength": s}``.

    Notes
    -----
    Prandtl's F = F_tip F_hub stays in the momentum balance; the force coefficients of the
    blade element (in the balance and in the loads) are multiplied by F1^s:

    .. math::
        F_1 = \\frac{2}{π}\\arccos\\exp\\left(−g\\,\\frac{B(R − r)}{2 r |\\sin φ|}\\right),\\qquad
        g = \\exp(−c_1 (B λ − c_2)) + c_3

    with λ = ΩR/V. s = 0 is Prandtl's model, s = 1 Shen's (C_n, C_t corrected by F1, which
    makes the loads vanish at the tip), s > 1 stronger still; s < 0 (weaker) is allowed so
    that s = 0 lies inside the bounds.

    A **model-form** parameter (``kind = "model_form"``): Prandtl's factor is the BEM's own
    approximation of a finite number of blades, so a diagnosis that names it says the misfit is
    the induction model's, not a missing physical effect.

    Fingerprint: the error sits at η > 0.9 and grows with λ; tip-gauge loads (``fn@0.95``,
    ``ft@0.95``) are off while root loads and spanwise loads inboard fit.

    References
    ----------
    W.Z. Shen, R. Mikkelsen, J.N. Sørensen, C. Bak, Tip loss corrections for wind turbine
    computations, Wind Energy 8 (2005) 457-475.
    """

    name = "tip_loss"
    stage = "induction"
    kind = "model_form"
    fingerprint = ("error at r/R > 0.9 growing with tip-speed ratio; tip-gauge loads (fn@0.95) off while root "
                   "loads fit")
    OPTIONS = {"c1": 0.125, "c2": 21.0, "c3": 0.1}
    PARAMETERS = (Parameter("tip_loss_strength", 0.0, -1.0, 3.0, 0.25, "-", "effect",
                            description="exponent s of Shen's F1 on the blade-element forces (0 = Prandtl, "
                                        "1 = Shen et al. 2005)", prior_std=1.0),)

    def shen_factor(self, phi, ctx):
        """Shen's F1 [-] at inflow angle ``phi`` [rad] (array or Dual)."""
        o = self.options
        B = ctx.rotor.n_blades
        g = dl.exp(-float(o["c1"]) * (B * ctx.tip_speed_ratio - float(o["c2"]))) + float(o["c3"])
        f = g * (B * (ctx.rotor.tip_radius - ctx.r) / (2.0 * ctx.r)) / dl.absolute(dl.sin(phi))
        return (2.0 / np.pi) * dl.arccos(dl.exp(-1.0 * f))

    def apply(self, theta, losses, ctx):
        (s,) = theta
        factor = dl.exp(s * dl.log(self.shen_factor(losses.phi, ctx)))
        return losses.replace(load=losses.load * factor)
