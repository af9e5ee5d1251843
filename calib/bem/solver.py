"""Native steady BEM: all sections of all operating points and azimuth sectors at once.

The flow follows CCBlade (Ning 2014): local velocities from precone, precurve,
presweep, tilt, yaw and shear per azimuth sector; Ning's residual solved by a
bracketed vectorized iteration; loads integrated along the blade path and averaged
over the sectors. Sensitivities come from the implicit-function theorem at the root
with exact partials (forward-mode duals of the same equations).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.bem import dual as dl
from calib.bem.kinematics import curvature, wind_components
from calib.bem.multiple_roots import (SCAN_STEP_DEG, WINDOW_DEG, SlopeEnvelope, lowest_roots,
                                      needs_search)
from calib.bem.polar_grid import SectionPolars
from calib.bem.residual import SectionGeometry, section_equations, section_loads
from calib.bem.rootfind import bracket, solve_brackets
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.types import OperatingConditions, Status, StatusCounts
from calib.rotor.geometry import Rotor

RESIDUAL_TOL = 1e-8
"""A section counts as converged when |R(φ*)| is below this [-]."""

INDUCTION_LIMIT = 2.0
"""Largest |a| accepted at a converged section [-] (see :func:`solve_bem`, Notes)."""


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
    kinematic_viscosity: float = 1.81e-5 / 1.225
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
class SectionSensitivities:
    """Total derivatives of section quantities at the BEM root.

    Each entry is a dict quantity -> ndarray (n_points, n_sectors, n_stations), for the
    quantities ``Np``, ``Tp`` [N/m], ``cn``, ``ct`` [-] (chord axes) and ``alpha_deg``.

    Attributes
    ----------
    d_cl, d_cd : dict
        Derivative with respect to an additive change of C_L / C_D at the section.
    d_pitch : dict
        Per degree of collective pitch offset.
    d_wind_scale : dict
        Per unit wind-speed scale factor.
    basis_index, basis_value : ndarray, shape (n_points, n_sectors, n_stations, 4)
        Correction shape functions active at each section (when a grid is used).
    """

    d_cl: dict
    d_cd: dict
    d_pitch: dict
    d_wind_scale: dict
    basis_index: np.ndarray | None = None
    basis_value: np.ndarray | None = None


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


def _check_conditions(conditions: OperatingConditions):
    """Per-point validity of the operating conditions: (bad mask, messages)."""
    n = len(conditions)
    msgs = [""] * n
    bad = np.zeros(n, bool)
    checks = (("wind_speed", conditions.wind_speed, lambda v: v > 0, "wind speed must be > 0 m/s"),
              ("rotor_speed", conditions.rotor_speed, lambda v: v > 0,
               "rotor speed must be > 0 rpm (parked rotors are outside the steady BEM)"),
              ("pitch", conditions.pitch, lambda v: np.abs(v) <= 180, "pitch must lie in [-180, 180] deg"),
              ("air_density", conditions.air_density, lambda v: v > 0, "air density must be > 0 kg/m^3"),
              ("yaw", conditions.yaw, lambda v: np.abs(v) < 90, "yaw must lie in (-90, 90) deg"))
    for name, v, ok, text in checks:
        with np.errstate(invalid="ignore"):
            fail = ~np.isfinite(v) | ~ok(v)
        for k in np.flatnonzero(fail & ~bad):
            msgs[k] = f"invalid input: {name} = {v[k]!r}; {text}"
        bad |= fail
    return bad, msgs


def solve_bem(rotor: Rotor, conditions: OperatingConditions, settings: BemSettings | None = None,
              grid: CorrectionGrid | None = None, p=None, pitch_offset: float = 0.0,
              wind_scale: float = 1.0, sensitivities: bool = False,
              polars: SectionPolars | None = None) -> BemResult:
    """Solve the steady BEM for a batch of operating points.

    Parameters
    ----------
    rotor : Rotor
    conditions : OperatingConditions
        Wind speed [m/s], rotor speed [rpm], pitch [deg], air density [kg/m^3], yaw [deg].
    settings : BemSettings, optional
    grid : CorrectionGrid, optional
        Correction field applied to every section's C_L and C_D.
    p : array_like, shape (grid.n_params,), optional
        Nodal corrections ``[p^L; p^D]`` [-]; zeros if omitted.
    pitch_offset : float
        Collective pitch offset added to every point [deg] (nuisance parameter).
    wind_scale : float
        Factor on the wind speed [-] (nuisance parameter: anemometry, blockage).
    sensitivities : bool
        Also return exact section sensitivities (for :mod:`calib.bem.jacobian`).
    polars : SectionPolars, optional
        Pre-built look-up tables (re-used across calls by :class:`BemModel`).

    Returns
    -------
    BemResult
        Every point has a status; failed points have NaN values and a message.

    Notes
    -----
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
    polars = polars or SectionPolars.from_rotor(rotor, smoothing=settings.polar_smoothing,
                                                kinematic_viscosity=settings.kinematic_viscosity)
    if grid is not None:
        p = np.zeros(grid.n_params) if p is None else np.asarray(p, float)
        if p.shape != (grid.n_params,) or not np.all(np.isfinite(p)):
            raise InputError(f"expected {grid.n_params} finite correction values, got shape {p.shape}",
                             "solve_bem", field="p")
    for name, v in (("pitch_offset", pitch_offset), ("wind_scale", wind_scale)):
        if not np.isfinite(v):
            raise InputError(f"must be finite, got {v!r}", "solve_bem", field=name)
    n_pts = len(conditions)
    n_sec = settings.sectors_for(rotor, conditions)
    n_st = rotor.n_stations
    bad_pt, msgs = _check_conditions(conditions)
    if not np.isfinite(rotor.hub_height) and settings.shear_exponent != 0.0:
        raise InputError("wind shear needs a finite hub height", rotor.source, field="hub_height")

    # ---- kinematics per (point, sector, station)
    pc = np.radians(rotor.precone_deg)
    x_az, y_az, z_az, cone, _ = curvature(rotor.r, rotor.precurve, rotor.presweep, pc)
    omega = conditions.rotor_speed * np.pi / 30.0
    wind = np.where(bad_pt, 1.0, conditions.wind_speed * wind_scale)
    azimuth = np.linspace(0.0, 2 * np.pi, n_sec + 1)[:-1]
    tilt = np.radians(rotor.tilt_deg) if settings.use_tilt else 0.0
    vx, vy, vxw, vyw = wind_components(x_az, y_az, z_az, cone, azimuth, wind, np.where(bad_pt, 1.0, omega),
                                       np.radians(np.where(bad_pt, 0.0, conditions.yaw)), tilt,
                                       rotor.hub_height, settings.shear_exponent)
    if wind_scale != 0.0:
        vxw, vyw = vxw / wind_scale, vyw / wind_scale   # d v / d wind_scale

    interior = interior_stations(rotor)
    shape = (n_pts, n_sec, n_st)
    station = np.broadcast_to(np.arange(n_st), shape)
    pitch = np.radians(np.where(bad_pt, 0.0, conditions.pitch) + pitch_offset)
    theta = np.radians(rotor.twist_deg)[None, None, :] + pitch[:, None, None]
    theta = np.broadcast_to(theta, shape)
    eta = np.broadcast_to(rotor.eta, shape)
    rho = np.broadcast_to(conditions.air_density[:, None, None], shape)
    active = np.broadcast_to(interior, shape) & ~bad_pt[:, None, None] & (vx > 0)

    sel = np.flatnonzero(active.reshape(-1))
    f_station, f_theta, f_eta = station.reshape(-1)[sel], theta.reshape(-1)[sel], eta.reshape(-1)[sel]
    f_vx, f_vy = vx.reshape(-1)[sel], vy.reshape(-1)[sel]
    r_full = np.broadcast_to(rotor.r, shape).reshape(-1)[sel]
    c_full = np.broadcast_to(rotor.chord, shape).reshape(-1)[sel]
    geo = SectionGeometry(r_full, c_full, rotor.n_blades * c_full / (2 * np.pi * r_full),
                          rotor.hub_radius, rotor.tip_radius, rotor.n_blades)
    opts = dict(tip_loss=settings.tip_loss, hub_loss=settings.hub_loss,
                drag_in_axial_induction=settings.drag_in_axial_induction,
                drag_in_tangential_induction=settings.drag_in_tangential_induction,
                wake_rotation=settings.wake_rotation)

    def coefficients(idx, phi):
        alpha_deg = np.degrees(phi - f_theta[idx])
        cl, cd, dcl, dcd = polars.lookup(alpha_deg, f_station[idx])
        if grid is not None:
            dl_, dd_, sl_, sd_ = grid.evaluate(p, alpha_deg, f_eta[idx])
            cl, cd, dcl, dcd = cl + dl_, cd + dd_, dcl + sl_, dcd + sd_
        return alpha_deg, cl, cd, dcl, dcd

    def residual(idx, phi):
        _, cl, cd, _, _ = coefficients(idx, phi)
        eq = section_equations(phi, cl, cd, f_vx[idx], f_vy[idx], geo.take(idx), **opts)
        return eq["residual"]

    lo, hi, flo, fhi, found = bracket(residual, sel.size)
    phi, fphi, iters = solve_brackets(residual, lo, hi, flo, fhi, found, max_iter=settings.max_iter)
    conv = found & np.isfinite(fphi) & (np.abs(fphi) <= RESIDUAL_TOL)
    n_roots = conv.astype(int)
    if settings.search_multiple_roots and conv.any():
        # screen: a negative lift slope within the window (stall), then the exact slope budget
        envelope = SlopeEnvelope.build(polars, WINDOW_DEG, grid, p, rotor.eta)
        ci = np.flatnonzero(conv)
        slopes = envelope.at(np.degrees(phi[ci] - f_theta[ci]), f_station[ci])
        stalled = slopes[0] < 0.0
        ci, slopes = ci[stalled], tuple(v[stalled] for v in slopes)
        _, cl_c, cd_c, _, _ = coefficients(ci, phi[ci])
        d0, d_cl, d_cd = _residual_partials(phi[ci], cl_c, cd_c, f_vx[ci], f_vy[ci], geo.take(ci), opts)
        search = np.zeros(sel.size, bool)
        search[ci] = needs_search(d0, d_cl, d_cd, slopes)
        phi, fphi, n_found = lowest_roots(residual, phi, fphi, lo, hi, search, np.radians(SCAN_STEP_DEG),
                                          np.radians(WINDOW_DEG), RESIDUAL_TOL, max_iter=settings.max_iter)
        n_roots = np.where(conv, n_found, 0)

    # ---- section quantities at the root (duals when sensitivities are wanted)
    allidx = np.arange(sel.size)
    phi_eval = np.where(conv, phi, 0.5 * np.pi)
    alpha_deg, cl, cd, dcl, dcd = coefficients(allidx, phi_eval)
    if sensitivities:
        # seeds: 0 phi, 1 theta, 2 vx, 3 vy, 4 additive dCL, 5 additive dCD
        k = 6
        phi_d = dl.Dual.seed(phi_eval, k, 0)
        theta_d = dl.Dual.seed(f_theta, k, 1)
        vx_d, vy_d = dl.Dual.seed(f_vx, k, 2), dl.Dual.seed(f_vy, k, 3)
        slope_cl, slope_cd = np.degrees(dcl), np.degrees(dcd)   # per rad
        d_cl = np.zeros((sel.size, k)); d_cl[:, 0], d_cl[:, 1], d_cl[:, 4] = slope_cl, -slope_cl, 1.0
        d_cd = np.zeros((sel.size, k)); d_cd[:, 0], d_cd[:, 1], d_cd[:, 5] = slope_cd, -slope_cd, 1.0
        cl_in, cd_in = dl.Dual(cl, d_cl), dl.Dual(cd, d_cd)
    else:
        phi_d, theta_d, vx_d, vy_d, cl_in, cd_in = phi_eval, f_theta, f_vx, f_vy, cl, cd
    eq = section_equations(phi_d, cl_in, cd_in, vx_d, vy_d, geo, **opts)
    rho_f = rho.reshape(-1)[sel]
    loads = section_loads(eq, vx_d, vy_d, geo.chord, rho_f)
    alpha_rad = phi_d - theta_d
    cn_chord = cl_in * dl.cos(alpha_rad) + cd_in * dl.sin(alpha_rad)
    ct_chord = cl_in * dl.sin(alpha_rad) - cd_in * dl.cos(alpha_rad)
    quantities = {"Np": loads["Np"], "Tp": loads["Tp"], "cn": cn_chord, "ct": ct_chord}

    def scatter(values, fill=0.0):
        out = np.full(n_pts * n_sec * n_st, fill)
        out[sel] = np.where(conv, values, np.nan)
        return out.reshape(shape)

    sections = {"phi": scatter(phi_eval), "alpha_deg": scatter(alpha_deg), "cl": scatter(cl),
                "cd": scatter(cd), "a": scatter(dl.value(eq["a"])), "ap": scatter(dl.value(eq["ap"])),
                "W": scatter(dl.value(loads["W"])), "residual": scatter(fphi),
                "iterations": scatter(iters.astype(float)), "n_roots": scatter(n_roots.astype(float))}
    for name, q in quantities.items():
        sections[name] = scatter(dl.value(q))

    # ---- per-point status
    def per_section(values):
        full = np.zeros(n_pts * n_sec * n_st, bool)
        full[sel] = values
        return full.reshape(shape)

    a_value = dl.value(eq["a"])
    with np.errstate(invalid="ignore"):
        wild = conv & ~(np.abs(a_value) <= INDUCTION_LIMIT)
    flags = {"failed": per_section(~conv), "negative_drag": per_section(cd <= 0.0),
             "reversed_flow": np.broadcast_to(interior, shape) & ~bad_pt[:, None, None] & ~(vx > 0),
             "wild_induction": per_section(wild), "multiple_roots": per_section(n_roots > 1)}
    status, msgs = _point_status(flags, sections["a"], bad_pt, msgs, rotor.eta)
    multiple = flags["multiple_roots"].any(axis=(1, 2)) & ~bad_pt
    n_multiple = flags["multiple_roots"].sum(axis=(1, 2))

    # ---- rotor quantities
    w = integration_weights(rotor, interior)
    B = rotor.n_blades
    Np, Tp = sections["Np"], sections["Tp"]
    thrust = B * np.einsum("ksi,i->k", Np, w["thrust"]) / n_sec
    torque = B * np.einsum("ksi,i->k", Tp, w["torque"]) / n_sec
    flap = np.einsum("ksi,i->k", Np, w["flap_root"]) / n_sec
    edge = np.einsum("ksi,i->k", Tp, w["flap_root"]) / n_sec
    flap_hub = np.einsum("ksi,i->k", Np, w["flap_hub"]) / n_sec
    with np.errstate(invalid="ignore"):
        power = torque * omega
    failed = status != Status.CONVERGED
    q_dyn = 0.5 * conditions.air_density * conditions.wind_speed ** 2
    area, radius = rotor.swept_area, rotor.rotor_radius
    with np.errstate(all="ignore"):
        cp = power / (q_dyn * area * conditions.wind_speed)
        ct_ = thrust / (q_dyn * area)
        cq = torque / (q_dyn * area * radius)
    outs = [power, thrust, torque, flap, edge, flap_hub, cp, ct_, cq]
    for arr in outs:
        arr[failed] = np.nan

    sens = None
    if sensitivities:
        sens = _section_sensitivities(eq, quantities, alpha_rad, conv, sel, shape, vxw, vyw, grid,
                                      sections, rotor)
    return BemResult(*outs, status=status, messages=tuple(msgs), sections=sections, weights=w,
                     omega=omega, n_sectors=n_sec, multiple_roots=multiple, n_multiple_root_sections=n_multiple,
                     rotor=rotor, sensitivities=sens)


def _residual_partials(phi, cl, cd, vx, vy, geo: SectionGeometry, opts: dict, rel_step: float = 1e-6):
    """∂R/∂φ at fixed C_L, C_D [1/rad], ∂R/∂C_L and ∂R/∂C_D [-] at given sections.

    One-sided differences of step ``rel_step`` in one batched call (cheaper than dual numbers
    here; they only screen sections for a search, see :mod:`calib.bem.multiple_roots`).
    """
    n = phi.size
    h = rel_step * np.maximum(1.0, np.abs(phi))
    hc = rel_step * np.maximum(1.0, np.abs(cl))
    hd = rel_step * np.maximum(1e-2, np.abs(cd))
    four = lambda x: np.concatenate([x, x, x, x])   # noqa: E731
    idx = np.concatenate([np.arange(n)] * 4)
    zero = np.zeros(n)
    eq = section_equations(four(phi) + np.concatenate([zero, h, zero, zero]),
                           four(cl) + np.concatenate([zero, zero, hc, zero]),
                           four(cd) + np.concatenate([zero, zero, zero, hd]),
                           four(vx), four(vy), geo.take(idx), **opts)
    r = eq["residual"].reshape(4, n)
    return (r[1] - r[0]) / h, (r[2] - r[0]) / hc, (r[3] - r[0]) / hd


def _point_status(flags: dict, a_sections, bad_pt, msgs: list, eta):
    """Status and message per point from per-section flags (n_points, n_sectors, n_stations).

    ``flags``: ``failed`` (no converged root), ``negative_drag`` (C_D <= 0), ``reversed_flow``
    (V_x <= 0), ``wild_induction`` (|a| > INDUCTION_LIMIT), ``multiple_roots`` (several roots;
    a note only, the status is unchanged).
    """
    status = np.full(bad_pt.size, int(Status.CONVERGED))
    status[bad_pt] = int(Status.INVALID_INPUT)
    trouble = flags["failed"] | flags["negative_drag"] | flags["reversed_flow"] | flags["wild_induction"]
    for kpt in np.flatnonzero(~bad_pt & (trouble | flags["multiple_roots"]).any(axis=(1, 2))):
        parts = []
        nd = int(flags["negative_drag"][kpt].sum())
        if nd:
            status[kpt] = int(Status.INVALID_INPUT)
            parts.append(f"C_D <= 0 at {nd} section(s) (corrected polar; the BEM needs positive drag)")
        elif trouble[kpt].any():
            status[kpt] = int(Status.NOT_CONVERGED)
        nf = int(flags["failed"][kpt].sum())
        if nf:
            parts.append(f"{nf} section(s) without a converged root (no sign change of the residual "
                         f"in Ning's brackets or |R| > {RESIDUAL_TOL:g})")
        nr = int(flags["reversed_flow"][kpt].sum())
        if nr:
            parts.append(f"{nr} section(s) with reversed inflow (V_x <= 0)")
        wild = flags["wild_induction"][kpt]
        if wild.any():
            a = np.where(wild, a_sections[kpt], 0.0)
            s_, i_ = np.unravel_index(np.argmax(np.abs(a)), a.shape)
            parts.append(f"axial induction outside the physical range |a| <= {INDUCTION_LIMIT:g} at "
                         f"{int(wild.sum())} section(s), e.g. a = {a[s_, i_]:.3g} at r/R = {eta[i_]:.3f} "
                         f"(induced velocity above twice the wind speed: no steady momentum balance)")
        multi = flags["multiple_roots"][kpt]
        if multi.any():
            where = ", ".join(f"{e:.3f}" for e in eta[np.flatnonzero(multi.any(axis=0))])
            parts.append(f"note: {int(multi.sum())} section(s) with several roots of the residual in "
                         f"their bracket (r/R = {where}); the root of smallest |φ| (least stalled) is used")
        msgs[kpt] = "BEM: " + "; ".join(parts)
    return status, msgs


def _section_sensitivities(eq, quantities, alpha_rad, conv, sel, shape, vxw, vyw, grid, sections, rotor):
    """Implicit-function total derivatives of section quantities (Ning 2014, §3)."""
    R = eq["residual"]
    r_phi = R.d[:, 0]
    with np.errstate(all="ignore"):
        dphi = -R.d / r_phi[:, None]          # dφ/d(seed) for seeds 1..5 (column 0 unused)
    size = int(np.prod(shape))
    f_vxw, f_vyw = vxw.reshape(-1)[sel], vyw.reshape(-1)[sel]

    def total(q):
        d = q.d[:, 1:] + q.d[:, [0]] * dphi[:, 1:]    # columns: theta, vx, vy, dcl, dcd
        return d

    out = {"d_cl": {}, "d_cd": {}, "d_pitch": {}, "d_wind_scale": {}}
    qs = dict(quantities)
    qs["alpha_deg"] = alpha_rad * (180.0 / np.pi)
    for name, q in qs.items():
        d = total(q)
        per = {"d_pitch": d[:, 0] * (np.pi / 180.0),
               "d_wind_scale": d[:, 1] * f_vxw + d[:, 2] * f_vyw,
               "d_cl": d[:, 3], "d_cd": d[:, 4]}
        for key, v in per.items():
            full = np.zeros(size)
            full[sel] = np.where(conv, v, 0.0)
            out[key][name] = full.reshape(shape)
    bi = bv = None
    if grid is not None:
        idx, val, _ = grid.basis(sections["alpha_deg"], np.broadcast_to(rotor.eta, shape))
        mask = np.isfinite(sections["alpha_deg"])[..., None]
        bi, bv = np.where(mask, idx, 0), np.where(mask, val, 0.0)
    return SectionSensitivities(out["d_cl"], out["d_cd"], out["d_pitch"], out["d_wind_scale"], bi, bv)
