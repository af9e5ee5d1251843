"""Native steady BEM: all sections of all operating points and azimuth sectors at once.

The flow follows CCBlade (Ning 2014): local velocities from precone, precurve,
presweep, tilt, yaw and shear per azimuth sector; Ning's residual solved by a
bracketed vectorized iteration; loads integrated along the blade path and averaged
over the sectors. Sensitivities come from the implicit-function theorem at the root
with exact partials (forward-mode duals of the same equations).

Here: the settings, the result, the station weights and :func:`solve_bem`, which sets a
batch up and adds up the rotor quantities. The solve at an inflow and its fixed point when
the inflow reads the thrust are :mod:`calib.bem.fixed_point`, the status of each point
:mod:`calib.bem.point_status`, the derivatives :mod:`calib.bem.sensitivities`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.bem.chain import EffectChain
from calib.bem.fixed_point import BatchSolve
from calib.bem.jacobian import SectionSensitivities
from calib.bem.kinematics import curvature
from calib.bem.point_status import check_conditions, section_fields, status_per_point
from calib.bem.polar_grid import AIR_KINEMATIC_VISCOSITY, SectionPolars, station_reynolds
from calib.bem.sensitivities import batch_sensitivities
from calib.bem.stages import PointContext, RotorData
from calib.errors import InputError
from calib.types import OperatingConditions, Status, StatusCounts
from calib.rotor.geometry import Rotor

__all__ = ["BemResult", "BemSettings", "integration_weights", "interior_stations", "solve_bem"]


@dataclass(frozen=True)
class BemSettings:
    """Options of the native BEM.

    Parameters
    ----------
    tip_loss, hub_loss : bool
        Prandtl tip / hub loss factors.
    drag_in_axial_induction, drag_in_tangential_induction : bool
        Include C_D in the force coefficients that drive the axial (κ) and tangential (κ')
        induction, separately (AeroDyn's ``AIDrag``, ``TIDrag``; CCBlade's ``useCd`` sets
        both). Ning (2014) recommends drag in the induction. These switches act on the
        induction only: the loads always contain the drag.
    wake_rotation : bool
        Tangential induction a'.
    n_sectors : int or None
        Azimuth sectors averaged per point; ``None`` picks 1 for an axisymmetric case
        (no tilt, yaw or shear) and 4 otherwise (as CCBlade).
    shear_exponent : float
        Power-law wind-shear exponent [-].
    use_tilt : bool
        Apply the rotor's shaft tilt to the inflow.
    max_iter : int
        Iteration limit of the root search.
    search_multiple_roots : bool
        Look for further roots of the residual near stall and keep the one of smallest |φ|
        (:mod:`calib.bem.multiple_roots`); off, the bracketing iteration's root is kept and
        nothing is flagged.
    kinematic_viscosity : float
        Of the fluid [m^2/s] (air at 15 °C: 1.81e-5 / 1.225; water: about 1e-6); sets the
        chord Reynolds numbers at which airfoils with several tables are interpolated.
    polar_smoothing : (s_cl, s_cd) or None
        Smoothing-spline bounds for the polars (``SectionPolars.from_rotor``); ``(0.01, 0.001)``
        reproduces CCBlade's CCAirfoil. None interpolates the tables exactly.
    """

    tip_loss: bool = True
    hub_loss: bool = True
    drag_in_axial_induction: bool = True
    drag_in_tangential_induction: bool = True
    wake_rotation: bool = True
    n_sectors: int | None = None
    shear_exponent: float = 0.0
    use_tilt: bool = True
    max_iter: int = 100
    search_multiple_roots: bool = True
    kinematic_viscosity: float = AIR_KINEMATIC_VISCOSITY
    polar_smoothing: tuple | None = None

    def sectors_for(self, rotor: Rotor, conditions: OperatingConditions) -> int:
        if self.n_sectors is not None:
            if int(self.n_sectors) < 1:
                raise InputError(f"must be >= 1, got {self.n_sectors}", "BemSettings", field="n_sectors")
            return int(self.n_sectors)
        symmetric = (self.shear_exponent == 0.0 and (not self.use_tilt or rotor.tilt_deg == 0.0)
                     and np.all(conditions.yaw == 0.0))
        return 1 if symmetric else 4


@dataclass(frozen=True, eq=False)
class BemResult(StatusCounts):
    """Outputs of :func:`solve_bem`.

    Rotor quantities have shape (n_points,); section fields (``sections``) have shape
    (n_points, n_sectors, n_stations) and are zero at stations on the hub or tip.

    Attributes
    ----------
    power [W], thrust [N], torque [N m] : ndarray
    root_flap_moment, root_edge_moment : ndarray
        Out-of-plane and in-plane bending moment of one blade about the blade root
        (r = hub radius) [N m], azimuth-averaged.
    hub_flap_moment : ndarray
        Out-of-plane moment of one blade about the rotor centre [N m] (CCBlade's ``Mb``).
    cp, ct, cq : ndarray
        Power, thrust and torque coefficients [-] on the swept area.
    status : ndarray of int
        :class:`calib.types.Status` per point.
    messages : tuple of str
        Why a point failed; on a converged point, a note when it has sections with several roots.
    sections : dict of ndarray
        ``phi`` [rad], ``alpha_deg``, ``a``, ``ap``, ``cl``, ``cd``, ``cn``, ``ct`` (chord
        axes), ``Np``, ``Tp`` [N/m], ``W`` [m/s], ``residual``, ``iterations``, ``n_roots``
        (roots of the residual seen near the kept one; 1 where none was searched for).
    weights : dict
        Integration weights used for the rotor quantities (for sensitivities).
    multiple_roots : ndarray of bool, shape (n_points,)
        Points with at least one section whose residual has several roots in its bracket (the
        root of smallest |φ| is used; the status is unchanged).
    n_multiple_root_sections : ndarray of int, shape (n_points,)
        Number of such sections (over stations and sectors).
    sensitivities : SectionSensitivities or None
    inflow_wind_speed, inflow_pitch : ndarray, shape (n_points,)
        Inflow speed [m/s] and pitch [deg] after the effect chain's conditions stage (NaN at
        invalid points).
    """

    power: np.ndarray
    thrust: np.ndarray
    torque: np.ndarray
    root_flap_moment: np.ndarray
    root_edge_moment: np.ndarray
    hub_flap_moment: np.ndarray
    cp: np.ndarray
    ct: np.ndarray
    cq: np.ndarray
    status: np.ndarray
    messages: tuple
    sections: dict
    weights: dict
    omega: np.ndarray
    n_sectors: int
    multiple_roots: np.ndarray
    n_multiple_root_sections: np.ndarray
    rotor: Rotor = field(repr=False)
    sensitivities: SectionSensitivities | None = None
    inflow_wind_speed: np.ndarray | None = None
    inflow_pitch: np.ndarray | None = None


def interior_stations(rotor: Rotor) -> np.ndarray:
    """Stations strictly between hub and tip (the ones that carry load) [bool]."""
    tol = 1e-9 * rotor.tip_radius
    return (rotor.r > rotor.hub_radius + tol) & (rotor.r < rotor.tip_radius - tol)


def integration_weights(rotor: Rotor, interior: np.ndarray | None = None) -> dict:
    """Trapezoid weights along the blade path, with zero load at hub and tip (CCBlade).

    Returns
    -------
    dict of ndarray, shape (n_stations,)
        ``thrust`` (ds cos(cone)) [m], ``torque`` (ds z) [m^2], ``flap_root`` (ds (z - z_root))
        [m^2] and ``flap_hub`` (ds z) [m^2], such that e.g. thrust per blade = Σ w N'.
    """
    interior = interior_stations(rotor) if interior is None else interior
    r, pc = rotor.r, np.radians(rotor.precone_deg)
    keep_hub = int(r[0] > rotor.hub_radius * (1 + 1e-9))
    keep_tip = int(r[-1] < rotor.tip_radius * (1 - 1e-9))
    rf = np.concatenate([[rotor.hub_radius]] * keep_hub + [r] + [[rotor.tip_radius]] * keep_tip)
    cf = np.concatenate([[0.0]] * keep_hub + [rotor.precurve] + [[rotor.precurve_tip]] * keep_tip)
    sf = np.concatenate([[0.0]] * keep_hub + [rotor.presweep] + [[rotor.presweep_tip]] * keep_tip)
    x_az, y_az, z_az, cone, s = curvature(rf, cf, sf, pc)
    ds = np.zeros_like(s)
    ds[1:-1] = 0.5 * (s[2:] - s[:-2])
    ds[0], ds[-1] = 0.5 * (s[1] - s[0]), 0.5 * (s[-1] - s[-2])
    sl = slice(int(keep_hub), int(keep_hub) + r.size)
    ds, z, cone = ds[sl] * interior, z_az[sl], cone[sl]
    z_root = rotor.hub_radius * np.cos(pc)
    return {"thrust": ds * np.cos(cone), "torque": ds * z, "flap_root": ds * (z - z_root),
            "flap_hub": ds * z}


def solve_bem(rotor: Rotor, conditions: OperatingConditions, settings: BemSettings | None = None,
              effects=(), p=None, sensitivities: bool = False,
              polars: SectionPolars | None = None) -> BemResult:
    """Solve the steady BEM for a batch of operating points, through a chain of effects.

    Parameters
    ----------
    rotor : Rotor
    conditions : OperatingConditions
        Wind speed [m/s], rotor speed [rpm], pitch [deg], air density [kg/m^3], yaw [deg].
    settings : BemSettings, optional
    effects : sequence of effects or EffectChain
        The chain (:mod:`calib.bem.chain`; the library is :mod:`calib.effects`): e.g. the
        correction field, a pitch offset, a wind-speed scale. Empty: the nominal BEM.
    p : array_like, shape (n_params,), optional
        Values of the chain's parameters, in its order; nominal values if omitted.
    sensitivities : bool
        Also return exact derivatives (:class:`calib.bem.jacobian.SectionSensitivities`).
    polars : SectionPolars, optional
        Pre-built look-up tables (re-used across calls by :class:`BemModel`).

    Returns
    -------
    BemResult
        Every point has a status; failed points have NaN values and a message.

    Notes
    -----
    The stages run in the order conditions → (polar, induction inside the root search) →
    loads (:mod:`calib.bem.stages`). A conditions effect that reads the rotor thrust (e.g.
    wind-tunnel blockage) makes the inflow depend on the solution: the solve is then repeated
    with the thrust of the previous solve until the inflow speed changes by less than
    :data:`~calib.bem.fixed_point.FIXED_POINT_TOL` (relative) at every point, at most
    :data:`~calib.bem.fixed_point.FIXED_POINT_MAX_ITER` times (a point that does not settle
    is NOT_CONVERGED); the thrust is iterated by the secant method per point (a fixed-point
    step first; :mod:`calib.bem.fixed_point`). Its derivatives follow from the implicit
    function theorem at the fixed point, per point: with the thrust T(V, β, p) of the BEM
    and the inflow (V, β) = C(T, p) of the conditions stage,
    dT/dp = (∂T/∂p + ∂T/∂V ∂V/∂p + ∂T/∂β ∂β/∂p) / (1 − ∂T/∂V ∂V/∂T − ∂T/∂β ∂β/∂T)
    (:mod:`calib.bem.sensitivities`).

    A point is NOT_CONVERGED when a section has no converged root, and also when a converged
    section's axial induction lies outside ±:data:`INDUCTION_LIMIT` (= 2). Buhl's relation is
    a fit to windmill-state data for a up to about 1 (C_T ≈ 2 there) and Ning's propeller-brake
    branch extends momentum theory a little beyond; |a| > 2 says the induced velocity exceeds
    twice the wind speed, a rotor driving the flow (fan, vortex-ring or hover-like state, where
    a ∝ 1/V as V → 0) for which no steady stream-tube balance of this model holds. The bound is
    a round number clear of every section of the validation and benchmark cases (|a| <= 1 on
    the NREL 5-MW C_P surface, the IEA 3.4-MW table and Phase VI; |a| <= 1.82 on the NREL 5-MW
    down to λ = 30) and far from the a ≈ 19 of a rotor at minimum speed in 0.1 m/s wind.

    Sections whose residual has several roots in the bracket keep the root of smallest |φ|
    and flag the point (:mod:`calib.bem.multiple_roots`); the status stays CONVERGED.

    References
    ----------
    S.A. Ning, Wind Energy 17 (2014) 1327-1345 (method, bracketing, CCBlade conventions).
    M.L. Buhl, NREL/TP-500-36834 (2005) (range of the high-induction relation).
    """
    settings = settings or BemSettings()
    solve, pctx, bad_pt, msgs, w = _set_up(rotor, conditions, settings, effects, p, polars)
    inflow, bad_all, msgs, sec, roots, values, unsettled = solve.to_fixed_point(pctx, bad_pt, msgs, sensitivities)

    sections = section_fields(sec, roots, values)
    status, msgs, multiple, n_multiple = status_per_point(sec, roots, values, sections["a"], bad_all, msgs,
                                                           unsettled, rotor.eta)
    outs = _rotor_quantities(rotor, conditions, sections, w, solve.n_sec, status != Status.CONVERGED)
    omega = conditions.rotor_speed * np.pi / 30.0

    sens = None
    if sensitivities:
        sens = batch_sensitivities(solve.chain, values, roots, sec, pctx, solve.thrust_weights)
    return BemResult(*outs, status=status, messages=tuple(msgs), sections=sections, weights=w,
                     omega=omega, n_sectors=solve.n_sec, multiple_roots=multiple, n_multiple_root_sections=n_multiple,
                     rotor=rotor, sensitivities=sens,
                     inflow_wind_speed=np.where(bad_all, np.nan, inflow.wind_speed),
                     inflow_pitch=np.where(bad_all, np.nan, inflow.pitch))


def _set_up(rotor: Rotor, conditions: OperatingConditions, settings: BemSettings, effects, p,
            polars: SectionPolars | None) -> tuple[BatchSolve, PointContext, np.ndarray, list, dict]:
    """Everything a batch's solve needs before its conditions stage (see :func:`solve_bem`).

    Parameters
    ----------
    rotor, conditions, settings, effects, p, polars
        As :func:`solve_bem` (``settings`` not None).

    Returns
    -------
    solve : BatchSolve
        Polars, bound effect chain, number of sectors, interior stations and thrust weights
        of the batch.
    pctx : PointContext
        The measured conditions [m/s], [rpm], [deg], [kg/m^3] and the swept area [m^2].
    bad_pt : ndarray of bool, shape (n_points,)
        Points whose operating conditions are invalid.
    msgs : list of str
        Why, per point.
    w : dict of ndarray, shape (n_stations,)
        :func:`integration_weights` of the rotor.

    Raises
    ------
    InputError
        ``n_sectors`` < 1, or wind shear with a hub height that is not finite.
    """
    polars = polars or SectionPolars.from_rotor(rotor, smoothing=settings.polar_smoothing,
                                                kinematic_viscosity=settings.kinematic_viscosity)
    chain = (effects if isinstance(effects, EffectChain) else EffectChain(effects)).bind(p)
    n_sec = settings.sectors_for(rotor, conditions)
    bad_pt, msgs = check_conditions(conditions)
    if not np.isfinite(rotor.hub_height) and settings.shear_exponent != 0.0:
        raise InputError("wind shear needs a finite hub height", rotor.source, field="hub_height")
    interior = interior_stations(rotor)
    w = integration_weights(rotor, interior)
    rotor_data = _rotor_data(rotor, polars, settings)
    pctx = PointContext(conditions.wind_speed, conditions.rotor_speed, conditions.pitch, conditions.air_density,
                        rotor.swept_area)
    opts = dict(tip_loss=settings.tip_loss, hub_loss=settings.hub_loss,
                drag_in_axial_induction=settings.drag_in_axial_induction,
                drag_in_tangential_induction=settings.drag_in_tangential_induction,
                wake_rotation=settings.wake_rotation)
    thrust_weights = rotor.n_blades * w["thrust"] / n_sec
    solve = BatchSolve(rotor, conditions, settings, chain, polars, opts, n_sec, interior, rotor_data, thrust_weights)
    return solve, pctx, bad_pt, msgs, w


def _rotor_quantities(rotor, conditions, sections, w, n_sec, failed) -> list:
    """Power, thrust, torque, flap, edge and hub-flap moments, C_P, C_T, C_Q per point (NaN where failed)."""
    B = rotor.n_blades
    Np, Tp = sections["Np"], sections["Tp"]
    thrust = B * np.einsum("ksi,i->k", Np, w["thrust"]) / n_sec
    torque = B * np.einsum("ksi,i->k", Tp, w["torque"]) / n_sec
    flap = np.einsum("ksi,i->k", Np, w["flap_root"]) / n_sec
    edge = np.einsum("ksi,i->k", Tp, w["flap_root"]) / n_sec
    flap_hub = np.einsum("ksi,i->k", Np, w["flap_hub"]) / n_sec
    omega = conditions.rotor_speed * np.pi / 30.0
    with np.errstate(invalid="ignore"):
        power = torque * omega
    q_dyn = 0.5 * conditions.air_density * conditions.wind_speed ** 2
    area, radius = rotor.swept_area, rotor.rotor_radius
    with np.errstate(all="ignore"):
        cp = power / (q_dyn * area * conditions.wind_speed)
        ct = thrust / (q_dyn * area)
        cq = torque / (q_dyn * area * radius)
    outs = [power, thrust, torque, flap, edge, flap_hub, cp, ct, cq]
    for arr in outs:
        arr[failed] = np.nan
    return outs


def _rotor_data(rotor: Rotor, polars: SectionPolars, settings: BemSettings) -> RotorData:
    return RotorData(rotor.n_blades, rotor.tip_radius, rotor.hub_radius, rotor.rotor_radius, polars,
                     station_reynolds(rotor, settings.kinematic_viscosity), settings.kinematic_viscosity)
