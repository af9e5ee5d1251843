"""Model form: the strength of the BEM's momentum balance against a vortex wake."""

from __future__ import annotations

from calib.effects.base import Effect
from calib.types import Parameter


class MomentumBalance(Effect):
    """A factor on the loss factor F of the momentum balance (induction stage, model form).

    Parameters
    ----------
    nominal : dict, optional
        ``{"momentum_factor": m}``.

    Notes
    -----
    Blade-element momentum theory balances the blade-element thrust of an annulus against
    the momentum flux through it, 4 F sin²φ a/(1 − a) = σ c_n (and the tangential
    counterpart), with Prandtl's F for a finite number of blades. A vortex method (a lifting
    line with a helical wake, a free wake, an actuator line) induces another velocity for the
    same loading: the wake's pitch, its expansion and the blades' mutual induction are
    approximated by the annulus and F. This effect scales the balance, F → m F, so that the
    induction at a given loading is about 1/m of the BEM's (κ = σ c_n / (4 m F sin²φ) in the
    momentum and Buhl branches alike):

    .. math::
        \\frac{a}{1 − a} = \\frac{σ\\,c_n}{4\\,m\\,F\\sin^2 φ}

    m = 1 is the BEM; m > 1 less induction (more power and thrust at high loading), m < 1
    more. It is a **model-form** parameter (``kind = "model_form"``): a diagnosis that names it
    says the misfit is the induction model's, not a missing physical effect. Bounds 0.7-1.5.

    Fingerprint: power and thrust off by an amount that grows with the rotor's loading (with
    the tip-speed ratio below rated, least at high pitch), power more than thrust; no change
    where the induction is small.

    References
    ----------
    H. Glauert, Airplane propellers, in W.F. Durand (ed.), Aerodynamic Theory, vol. IV,
    Springer (1935), div. L (the momentum balance of an annulus and the tip-loss factor).
    E. Branlard, Wind Turbine Aerodynamics and Vorticity-Based Methods, Springer (2017),
    ch. 8-13 (BEM against vortex-cylinder and helical-wake models of the same rotor).
    """

    name = "momentum_balance"
    stage = "induction"
    kind = "model_form"
    fingerprint = ("power and thrust off by an amount growing with the rotor loading (with tip-speed ratio below "
                   "rated), power more than thrust; nothing where the induction is small")
    PARAMETERS = (Parameter("momentum_factor", 1.0, 0.7, 1.5, 0.05, "-", "effect",
                            description="factor m on the momentum balance's loss factor F (1 = BEM)",
                            prior_std=0.1),)

    def apply(self, theta, losses, ctx):
        (m,) = theta
        return losses.replace(tip=losses.tip * m)
