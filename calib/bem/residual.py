"""The BEM section equations (Ning's residual in the inflow angle φ).

Written once for plain arrays and for :class:`calib.bem.dual.Dual` numbers, so the
same code gives values during the root search and exact partial derivatives at the
root.

Notes
-----
Per section, with inflow angle φ, lift and drag coefficients C_L, C_D, local
velocities V_x (normal to the rotor plane) and V_y (in-plane), local solidity
σ' = B c / (2 π r):

.. math::
    c_n = C_L \\cos φ + C_D \\sin φ,\\quad c_t = C_L \\sin φ - C_D \\cos φ

    F = F_{tip} F_{hub},\\quad
    F_{tip} = \\tfrac{2}{π}\\arccos e^{-B(R-r)/(2 r |\\sin φ|)},\\quad
    F_{hub} = \\tfrac{2}{π}\\arccos e^{-B(r-R_h)/(2 R_h |\\sin φ|)}

    κ = \\frac{σ' c_n}{4 F \\sin^2 φ},\\quad κ' = \\frac{σ' c_t}{4 F \\sin φ \\cos φ}

    a = κ/(1+κ)\\ (κ ≤ 2/3),\\ \\text{else Buhl},\\quad a' = κ'/(1-κ')

    R(φ) = \\frac{\\sin φ}{1-a} - \\frac{\\cos φ}{λ_r}(1-κ')\\ (φ > 0),\\qquad
    R(φ) = \\sin φ (1-κ) - \\frac{\\cos φ}{λ_r}(1-κ')\\ (φ < 0)

with λ_r = V_y / V_x. Loads per unit length N' = ½ρW²c c_n, T' = ½ρW²c c_t,
W² = (V_x(1-a))² + (V_y(1+a'))².
Drag can be left out of the induction alone, as AeroDyn's ``AIDrag`` / ``TIDrag``:
κ then uses C_L cos φ, κ' uses C_L sin φ, while N', T' keep the full c_n, c_t.

References
----------
S.A. Ning, A simple solution method for the blade element momentum equations with
guaranteed convergence, Wind Energy 17 (2014) 1327-1345.
M.L. Buhl, A new empirical relationship between thrust coefficient and induction
factor for the turbulent windmill state, NREL/TP-500-36834 (2005).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.bem import dual as dl
from calib.bem.stages import LossState

HALF_PI = 0.5 * np.pi


@dataclass(frozen=True)
class SectionGeometry:
    """Per-section constants, flattened to shape (n_sections,).

    r [m], chord [m], local solidity sigma [-], hub and tip radius [m], blade count B.
    """

    r: np.ndarray
    chord: np.ndarray
    sigma: np.ndarray
    hub_radius: float
    tip_radius: float
    n_blades: int

    def take(self, idx) -> "SectionGeometry":
        return SectionGeometry(self.r[idx], self.chord[idx], self.sigma[idx], self.hub_radius,
                               self.tip_radius, self.n_blades)


def prandtl_factors(phi, geo: SectionGeometry, tip_loss: bool, hub_loss: bool):
    """Prandtl's tip and hub loss factors (F_tip, F_hub) [-], 1.0 where switched off (docs/theory.md, Native BEM)."""
    s = dl.absolute(dl.sin(phi))
    B = geo.n_blades
    tip = hub = 1.0
    if tip_loss:
        f = B * (geo.tip_radius - geo.r) / (2.0 * geo.r) / s
        tip = (2.0 / np.pi) * dl.arccos(dl.exp(-f))
    if hub_loss:
        f = B * (geo.r - geo.hub_radius) / (2.0 * geo.hub_radius) / s
        hub = (2.0 / np.pi) * dl.arccos(dl.exp(-f))
    return tip, hub


def loss_factor(phi, geo: SectionGeometry, tip_loss: bool, hub_loss: bool):
    """Prandtl tip and hub loss factor F = F_tip F_hub [-] (docs/theory.md, Native BEM; Ning 2014 eq. 5)."""
    tip, hub = prandtl_factors(phi, geo, tip_loss, hub_loss)
    if not tip_loss:
        return hub
    return tip * hub if hub_loss else tip


def section_equations(phi, cl, cd, vx, vy, geo: SectionGeometry, *, tip_loss=True, hub_loss=True,
                      drag_in_axial_induction=True, drag_in_tangential_induction=True, wake_rotation=True,
                      losses=None):
    """Residual and induction of the BEM section equations.

    Parameters
    ----------
    phi : array or Dual, shape (n,)
        Inflow angle [rad].
    cl, cd : array or Dual, shape (n,)
        Lift and drag coefficients at α = φ - θ [-].
    vx, vy : array or Dual, shape (n,)
        Velocity normal to the rotor plane and in-plane (rotation) [m/s].
    geo : SectionGeometry
    tip_loss, hub_loss : bool
        Prandtl tip / hub loss factors.
    drag_in_axial_induction, drag_in_tangential_induction : bool
        Keep C_D in the force coefficient that drives κ (axial) / κ' (tangential induction),
        AeroDyn's ``AIDrag`` / ``TIDrag``. They act on the induction only: the returned
        ``cn``, ``ct`` (and hence the loads) always contain the drag.
    wake_rotation : bool
        Tangential induction a' (else a' = 0).
    losses : callable, optional
        The induction stage of an effect chain: ``losses(LossState) -> LossState``
        (:mod:`calib.bem.stages`). The momentum balance then uses F = tip · hub of the
        returned state, and the force coefficients C_L, C_D are multiplied by its ``load``
        factor (in the balance and in the loads alike).

    Returns
    -------
    dict
        ``residual`` [-], ``a``, ``ap`` (axial, tangential induction) [-], ``cn``, ``ct``
        (rotor axes, with drag) [-], ``F`` [-], ``load`` (factor on the force coefficients) [-].

    References
    ----------
    AeroDyn v15 user guide (J. Jonkman et al., NREL), input switches ``AIDrag``, ``TIDrag``;
    CCBlade's ``useCd`` (Ning 2014) is the two switches set together.
    """
    s = dl.sin(phi)
    c = dl.cos(phi)
    load = 1.0
    if losses is None:
        F = loss_factor(phi, geo, tip_loss, hub_loss)
    else:
        tip, hub = prandtl_factors(phi, geo, tip_loss, hub_loss)
        state = losses(LossState(phi, tip, hub))
        F, load = state.tip * state.hub, state.load
        cl, cd = cl * load, cd * load
    cn = cl * c + cd * s
    ct = cl * s - cd * c
    cn_induction = cn if drag_in_axial_induction else cl * c
    ct_induction = ct if drag_in_tangential_induction else cl * s
    k = geo.sigma * cn_induction / (4.0 * F * s * s)
    kp = geo.sigma * ct_induction / (4.0 * F * s * c)
    pos = dl.value(phi) > 0
    kv = dl.value(k)
    with np.errstate(all="ignore"):
        a_mom = k / (1.0 + k)
        g1 = 2.0 * F * k - (10.0 / 9.0 - F)
        g2 = 2.0 * F * k - F * (4.0 / 3.0 - F)
        g3 = 2.0 * F * k - (25.0 / 9.0 - 2.0 * F)
        g3v = dl.value(g3)
        singular = np.abs(g3v) < 1e-6
        g3_safe = dl.where(singular, 1.0, g3)
        a_buhl = dl.where(singular, 1.0 - 0.5 / dl.sqrt(g2), (g1 - dl.sqrt(g2)) / g3_safe)
        a_brake = dl.where(kv > 1.0, k / (k - 1.0), 0.0 * k)
        a = dl.where(pos, dl.where(kv <= 2.0 / 3.0, a_mom, a_buhl), a_brake)
        if not wake_rotation:
            kp = 0.0 * kp
        ap = kp / (1.0 - kp)
        lam = vy / vx
        res_pos = s / (1.0 - a) - c / lam * (1.0 - kp)
        res_neg = s * (1.0 - k) - c / lam * (1.0 - kp)
        residual = dl.where(pos, res_pos, res_neg)
    return {"residual": residual, "a": a, "ap": ap, "cn": cn, "ct": ct, "F": F, "load": load}


def section_loads(eq: dict, vx, vy, chord, rho):
    """Loads per unit length from a solved section.

    Returns
    -------
    dict
        ``W`` relative speed [m/s], ``Np`` normal (out-of-plane) and ``Tp`` tangential
        (in-plane, in the direction of rotation) force per unit length [N/m].
    """
    a, ap = eq["a"], eq["ap"]
    with np.errstate(all="ignore"):
        w2 = (vx * (1.0 - a)) ** 2 + (vy * (1.0 + ap)) ** 2
    q = 0.5 * rho * w2 * chord
    return {"W": dl.sqrt(w2), "Np": eq["cn"] * q, "Tp": eq["ct"] * q}
