"""The loaded sections of a batch at a given inflow: kinematics, root search, section pass.

Everything here is vectorized over the flattened active sections (points × sectors ×
stations that carry load). The polar and induction stages of the effect chain are
evaluated inside the residual, the loads stage after the solve; with ``k`` > 0 derivative
columns the section pass runs on dual numbers and :func:`eliminate_phi` applies the
implicit-function theorem at the root (Ning 2014).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np

from calib.bem import dual as dl
from calib.bem import kernel, kernel_chain
from calib.bem.chain import COL_PHI, COL_PITCH, COL_WIND, BoundChain
from calib.bem.kinematics import curvature, wind_components
from calib.bem.multiple_roots import (SCAN_STEP_DEG, SCREEN_MARGIN, WINDOW_DEG, SlopeEnvelope, lowest_roots,
                                      needs_search)
from calib.bem.residual import SectionGeometry, section_equations, section_loads
from calib.bem.rootfind import bracket, solve_brackets
from calib.bem.stages import LoadsState, PolarState, RotorData, SectionContext

RESIDUAL_TOL = 1e-8
"""A section counts as converged when |R(φ*)| is below this [-]."""

_TABLE_ENVELOPES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
"""Slope envelope of each SectionPolars' own tables (no polar effect), built at first use."""


@dataclass(frozen=True, eq=False)
class Sections:
    """The active sections of a batch at one inflow, flattened to shape (n,).

    Attributes
    ----------
    shape : tuple
        (n_points, n_sectors, n_stations).
    sel : ndarray of int
        Flat indices of the active sections (interior stations of valid points with V_x > 0).
    reversed_flow : ndarray of bool, shape ``shape``
        Interior sections of valid points with V_x <= 0.
    station, theta, vx, vy, vx_per_wind, vy_per_wind, rho : ndarray, shape (n,)
        Station index, pitch + twist [rad], velocities [m/s], their derivatives with respect
        to the inflow speed [-], air density [kg/m^3].
    geo : SectionGeometry
    ctx : SectionContext
        Plain values (the section pass builds a dual one).
    wind, omega : ndarray, shape (n,)
        The point's inflow speed [m/s] and rotor speed [rad/s].
    """

    shape: tuple
    sel: np.ndarray
    reversed_flow: np.ndarray
    station: np.ndarray
    theta: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    vx_per_wind: np.ndarray
    vy_per_wind: np.ndarray
    rho: np.ndarray
    geo: SectionGeometry
    ctx: SectionContext
    wind: np.ndarray
    omega: np.ndarray

    @property
    def n(self) -> int:
        return int(self.sel.size)


def build_sections(rotor, conditions, settings, n_sec: int, rotor_data: RotorData, interior, wind, pitch_deg,
                   bad_pt) -> Sections:
    """Kinematics of every section at inflow speed ``wind`` [m/s] and pitch ``pitch_deg`` [deg] per point."""
    n_pts, n_st = len(conditions), rotor.n_stations
    pc = np.radians(rotor.precone_deg)
    x_az, y_az, z_az, cone, _ = curvature(rotor.r, rotor.precurve, rotor.presweep, pc)
    omega = conditions.rotor_speed * np.pi / 30.0
    wind = np.where(bad_pt, 1.0, wind)
    azimuth = np.linspace(0.0, 2 * np.pi, n_sec + 1)[:-1]
    tilt = np.radians(rotor.tilt_deg) if settings.use_tilt else 0.0
    vx, vy, vxw, vyw = wind_components(x_az, y_az, z_az, cone, azimuth, wind, np.where(bad_pt, 1.0, omega),
                                       np.radians(np.where(bad_pt, 0.0, conditions.yaw)), tilt,
                                       rotor.hub_height, settings.shear_exponent)
    shape = (n_pts, n_sec, n_st)
    pitch = np.radians(np.where(bad_pt, 0.0, pitch_deg))
    theta = np.broadcast_to(np.radians(rotor.twist_deg)[None, None, :] + pitch[:, None, None], shape)
    loaded = np.broadcast_to(interior, shape) & ~bad_pt[:, None, None]
    active = loaded & (vx > 0)
    sel = np.flatnonzero(active.reshape(-1))

    def flat(x):
        return np.broadcast_to(x, shape).reshape(-1)[sel]

    station = flat(np.arange(n_st))
    r, chord = flat(rotor.r), flat(rotor.chord)
    geo = SectionGeometry(r, chord, rotor.n_blades * chord / (2 * np.pi * r), rotor.hub_radius, rotor.tip_radius,
                          rotor.n_blades)
    wind_s, omega_s = flat(wind[:, None, None]), flat(omega[:, None, None])
    f_vx, f_vy = flat(vx), flat(vy)
    with np.errstate(all="ignore"):
        ctx = SectionContext(station, r, chord, flat(rotor.eta), flat(rotor.twist_deg),
                             omega_s * rotor_data.rotor_radius / wind_s,
                             np.sqrt(f_vx * f_vx + f_vy * f_vy) * (chord / rotor_data.kinematic_viscosity), rotor_data)
    return Sections(shape, sel, loaded & ~(vx > 0), station, flat(theta), f_vx, f_vy, flat(vxw) / wind_s,
                    flat(vyw) / wind_s, flat(conditions.air_density[:, None, None]), geo, ctx, wind_s, omega_s)


def _induction(chain: BoundChain, ctx: SectionContext, k: int = 0):
    """The induction stage as the ``losses`` hook of :func:`section_equations` (None if empty)."""
    if not chain.has("induction"):
        return None
    return lambda state: chain.run("induction", state, ctx, k)


def _polar(chain: BoundChain, polars, sec: Sections, idx, phi):
    """Angle of attack [deg] and C_L, C_D [-] after the polar stage, plain values at sections ``idx``."""
    alpha_deg = np.degrees(phi - sec.theta[idx])
    cl, cd, _, _ = polars.lookup(alpha_deg, sec.station[idx])
    if chain.has("polar"):
        state = chain.run("polar", PolarState(alpha_deg, cl, cd), sec.ctx.take(idx))
        cl, cd = state.cl, state.cd
    return alpha_deg, cl, cd


@dataclass(frozen=True, eq=False)
class Roots:
    """Root of every active section.

    Attributes
    ----------
    phi, residual : ndarray, shape (n,)
        Inflow angle [rad] (π/2 where not converged) and residual there [-].
    converged : ndarray of bool
    iterations, n_roots : ndarray of int
    compiled : calib.bem.kernel.SectionKernel or None
        The compiled kernel that found them (it keeps its last evaluation of each section).
    """

    phi: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    iterations: np.ndarray
    n_roots: np.ndarray
    compiled: object = None


def find_roots(sec: Sections, chain: BoundChain, polars, settings, opts: dict, rotor) -> Roots:
    """Ning's brackets, the Anderson-Björck iteration and, near stall, the search for several roots.

    Without induction effects, and with no polar effect or one the kernel evaluates (a
    ``compiled_polar``: the correction field), the compiled kernel (:mod:`calib.bem.kernel`)
    runs the residual and the iteration when it is available: the same arithmetic, one pass.
    """
    compilable, field = kernel_chain.chain_form(chain)
    lib = kernel.library() if compilable else None
    if lib is not None:
        compiled = kernel.SectionKernel(lib, polars, sec, opts, field)
        residual = compiled.residual
        lo, hi, flo, fhi, found, phi, fphi, iters = compiled.solve(max_iter=settings.max_iter)
    else:
        def residual(idx, phi):
            _, cl, cd = _polar(chain, polars, sec, idx, phi)
            eq = section_equations(phi, cl, cd, sec.vx[idx], sec.vy[idx], sec.geo.take(idx),
                                   losses=_induction(chain, sec.ctx.take(idx)), **opts)
            return eq["residual"]

        lo, hi, flo, fhi, found = bracket(residual, sec.n)
        phi, fphi, iters = solve_brackets(residual, lo, hi, flo, fhi, found, max_iter=settings.max_iter)
    conv = found & np.isfinite(fphi) & (np.abs(fphi) <= RESIDUAL_TOL)
    n_roots = conv.astype(int)
    if settings.search_multiple_roots and conv.any():
        # screen: a negative lift slope within the window (stall), then the exact slope budget
        ci = np.flatnonzero(conv)
        if lib is not None and field is None:
            search = compiled.screen(ci, phi, slope_envelope(chain, polars, sec, rotor), SCREEN_MARGIN)
        elif lib is not None:       # the field's envelope on the converged sections' range, as below
            alpha_c = np.degrees(phi[ci] - sec.theta[ci])
            envelope = slope_envelope(chain, polars, sec, rotor, (alpha_c.min(), alpha_c.max()))
            search = compiled.screen(ci, phi, envelope, SCREEN_MARGIN)
        else:
            alpha_c = np.degrees(phi[ci] - sec.theta[ci])
            envelope = slope_envelope(chain, polars, sec, rotor, (alpha_c.min(), alpha_c.max()))
            slopes = envelope.at(alpha_c, sec.station[ci])
            stalled = slopes[0] < 0.0
            ci, slopes = ci[stalled], tuple(v[stalled] for v in slopes)
            _, cl_c, cd_c = _polar(chain, polars, sec, ci, phi[ci])
            d0, d_cl, d_cd = _residual_partials(phi[ci], cl_c, cd_c, sec.vx[ci], sec.vy[ci], sec.geo.take(ci), opts,
                                                _induction(chain, sec.ctx.take(np.concatenate([ci] * 4))))
            search = np.zeros(sec.n, bool)
            search[ci] = needs_search(d0, d_cl, d_cd, slopes)
        phi, fphi, n_found = lowest_roots(residual, phi, fphi, lo, hi, search, np.radians(SCAN_STEP_DEG),
                                          np.radians(WINDOW_DEG), RESIDUAL_TOL, max_iter=settings.max_iter)
        n_roots = np.where(conv, n_found, 0)
    return Roots(np.where(conv, phi, 0.5 * np.pi), fphi, conv, iters, n_roots, compiled if lib is not None else None)


def slope_envelope(chain: BoundChain, polars, sec: Sections, rotor, alpha_range=None) -> SlopeEnvelope:
    """Extreme dC/dα of the polars after the chain's polar stage, per station and α node.

    Without polar effects these are the tables' slopes. Otherwise the polar stage is
    tabulated with exact α-derivatives (duals) on every station's α grid, on the nodes of
    ``alpha_range`` (min, max) [deg] (the converged sections' angles) widened by the window;
    effects that read the flow (``uses_flow``) are tabulated at the four corners of the
    batch's range of tip-speed ratio and of each station's Reynolds number, and the envelope
    covers all four (exact bounds for effects whose slope is monotone in each of the two).
    """
    if not chain.has("polar"):
        if polars not in _TABLE_ENVELOPES:      # a function of the tables alone: once per SectionPolars
            _TABLE_ENVELOPES[polars] = SlopeEnvelope.build(polars.cl_slopes, polars.cd_slopes, polars.step_deg,
                                                           WINDOW_DEG)
        return _TABLE_ENVELOPES[polars]
    n_st, n_all = polars.cl_nodes.shape
    h = polars.step_deg
    first, last = 0, n_all - 1
    if alpha_range is not None:
        margin = WINDOW_DEG + 2 * h
        first = max(0, int(np.floor((alpha_range[0] - margin + 180.0) / h)))
        last = min(n_all - 1, int(np.ceil((alpha_range[1] + margin + 180.0) / h)))
    cols = slice(first, last + 1)
    n_grid = last + 1 - first
    station = np.repeat(np.arange(n_st), n_grid)
    alpha = dl.Dual(np.tile(polars.alpha_grid_deg[cols], n_st), np.ones((n_st * n_grid, 1)))
    cl = dl.Dual(polars.cl_nodes[:, cols].reshape(-1), polars.cl_slopes[:, cols].reshape(-1, 1))
    cd = dl.Dual(polars.cd_nodes[:, cols].reshape(-1), polars.cd_slopes[:, cols].reshape(-1, 1))
    base = dict(station=station, r=np.repeat(rotor.r, n_grid), chord=np.repeat(rotor.chord, n_grid),
                eta=np.repeat(rotor.eta, n_grid), twist_deg=np.repeat(rotor.twist_deg, n_grid), rotor=sec.ctx.rotor)
    corners = [(None, None)]
    if chain.polar_uses_flow and sec.n:
        lam = dl.value(sec.ctx.tip_speed_ratio)
        re = dl.value(sec.ctx.reynolds)
        re_lo = np.full(n_st, np.nan)
        re_hi = np.full(n_st, np.nan)
        np.fmin.at(re_lo, sec.station, re)
        np.fmax.at(re_hi, sec.station, re)
        corners = [(lv, rv) for lv in (np.nanmin(lam), np.nanmax(lam)) for rv in (re_lo, re_hi)]
    env = None
    for lam_c, re_c in corners:
        lam_v = np.full(station.size, 1.0 if lam_c is None else lam_c)
        re_v = np.ones(station.size) if re_c is None else np.repeat(np.nan_to_num(re_c, nan=1.0), n_grid)
        ctx = SectionContext(tip_speed_ratio=lam_v, reynolds=re_v, **base)
        state = chain.run("polar", PolarState(alpha, cl, cd), ctx)
        slopes = [(s.d[:, 0] if isinstance(s, dl.Dual) else np.zeros(station.size)).reshape(n_st, n_grid)
                  for s in (state.cl, state.cd)]
        e = SlopeEnvelope.build(slopes[0], slopes[1], h, WINDOW_DEG, first_node=first)
        env = e if env is None else env.union(e)
    return env


def _residual_partials(phi, cl, cd, vx, vy, geo: SectionGeometry, opts: dict, losses=None, rel_step: float = 1e-6):
    """∂R/∂φ at fixed C_L, C_D [1/rad], ∂R/∂C_L and ∂R/∂C_D [-] at given sections.

    One-sided differences of step ``rel_step`` in one batched call (cheaper than dual numbers
    here; they only screen sections for a search, see :mod:`calib.bem.multiple_roots`).
    ``losses``: the induction stage for the four stacked copies of the sections.
    """
    n = phi.size
    h = rel_step * np.maximum(1.0, np.abs(phi))
    hc = rel_step * np.maximum(1.0, np.abs(cl))
    hd = rel_step * np.maximum(1e-2, np.abs(cd))
    four = lambda x: np.concatenate([x, x, x, x])   # noqa: E731
    stacked = np.concatenate([np.arange(n)] * 4)
    zero = np.zeros(n)
    eq = section_equations(four(phi) + np.concatenate([zero, h, zero, zero]),
                           four(cl) + np.concatenate([zero, zero, hc, zero]),
                           four(cd) + np.concatenate([zero, zero, zero, hd]),
                           four(vx), four(vy), geo.take(stacked), losses=losses, **opts)
    r = eq["residual"].reshape(4, n)
    return (r[1] - r[0]) / h, (r[2] - r[0]) / hc, (r[3] - r[0]) / hd


@dataclass(frozen=True, eq=False)
class SectionValues:
    """Section quantities at the roots (plain values, or duals over the section columns).

    Attributes
    ----------
    alpha_deg, cl, cd : ndarray, shape (n,)
        Angle of attack [deg] and the polar stage's C_L, C_D [-] (plain).
    eq : dict
        :func:`section_equations` at the root.
    W : array or Dual
        Relative speed [m/s].
    quantities : dict
        ``Np``, ``Tp`` [N/m] (after the loads stage), ``cn``, ``ct`` [-] (chord axes), and with
        duals ``alpha_deg``.
    totals : dict or None
        :func:`eliminate_phi` of these, when the compiled kernel took that step already.
    """

    alpha_deg: np.ndarray
    cl: np.ndarray
    cd: np.ndarray
    eq: dict
    W: object
    quantities: dict
    totals: dict | None = None


def section_pass(sec: Sections, roots: Roots, chain: BoundChain, polars, opts: dict, k: int = 0) -> SectionValues:
    """Evaluate every section at its root; with ``k`` > 0, on duals over the chain's section columns.

    Columns: φ, pitch [rad], inflow speed [m/s], then the section-stage effects' columns
    (:mod:`calib.bem.chain`). Plain values come from the compiled kernel where it found the
    roots (:func:`find_roots`; the same arithmetic).
    """
    phi = roots.phi
    if k and roots.compiled is not None and not chain.has("loads") and k <= roots.compiled.MAX_COLUMNS:
        return SectionValues(*kernel_chain.compiled_pass(sec, roots, chain, k))
    if not k and roots.compiled is not None:        # no induction effects, the polar stage compiled (find_roots)
        v = roots.compiled.values(phi)
        Np, Tp = v["Np"], v["Tp"]
        if chain.has("loads"):
            state = chain.run("loads", LoadsState(Np, Tp), sec.ctx, k)
            Np, Tp = state.Np, state.Tp
        eq = {"residual": v["residual"], "a": v["a"], "ap": v["ap"], "cn": v["cn"], "ct": v["ct"], "F": v["F"],
              "load": 1.0}
        return SectionValues(v["alpha_deg"], v["cl"], v["cd"], eq, v["W"],
                             {"Np": Np, "Tp": Tp, "cn": v["cn_chord"], "ct": v["ct_chord"]})
    alpha_deg = np.degrees(phi - sec.theta)
    cl, cd, dcl, dcd = polars.lookup(alpha_deg, sec.station)
    ctx = sec.ctx
    if k:
        phi_x = dl.Dual.seed(phi, k, COL_PHI)
        theta_x = dl.Dual.seed(sec.theta, k, COL_PITCH)
        dv = np.zeros((sec.n, k))
        dv[:, COL_WIND] = 1.0
        vx = dl.Dual(sec.vx, dv * sec.vx_per_wind[:, None])
        vy = dl.Dual(sec.vy, dv * sec.vy_per_wind[:, None])
        wind = dl.Dual(sec.wind, dv)
        with np.errstate(all="ignore"):
            ctx = SectionContext(ctx.station, ctx.r, ctx.chord, ctx.eta, ctx.twist_deg,
                                 sec.omega * ctx.rotor.rotor_radius / wind,
                                 dl.sqrt(vx * vx + vy * vy) * (ctx.chord / ctx.rotor.kinematic_viscosity), ctx.rotor)
        alpha_rad = phi_x - theta_x
        alpha_x = dl.Dual(alpha_deg, alpha_rad.d * (180.0 / np.pi))
        cl_x = dl.Dual(cl, dcl[:, None] * alpha_x.d)
        cd_x = dl.Dual(cd, dcd[:, None] * alpha_x.d)
    else:
        phi_x, vx, vy = phi, sec.vx, sec.vy
        alpha_rad, alpha_x, cl_x, cd_x = phi - sec.theta, alpha_deg, cl, cd
    if chain.has("polar"):
        state = chain.run("polar", PolarState(alpha_x, cl_x, cd_x), ctx, k)
        cl_x, cd_x = state.cl, state.cd
    eq = section_equations(phi_x, cl_x, cd_x, vx, vy, sec.geo, losses=_induction(chain, ctx, k), **opts)
    loads = section_loads(eq, vx, vy, sec.geo.chord, sec.rho)
    Np, Tp = loads["Np"], loads["Tp"]
    if chain.has("loads"):
        state = chain.run("loads", LoadsState(Np, Tp), ctx, k)
        Np, Tp = state.Np, state.Tp
    cn = cl_x * dl.cos(alpha_rad) + cd_x * dl.sin(alpha_rad)
    ct = cl_x * dl.sin(alpha_rad) - cd_x * dl.cos(alpha_rad)
    if chain.has("induction"):
        cn, ct = cn * eq["load"], ct * eq["load"]
    quantities = {"Np": Np, "Tp": Tp, "cn": cn, "ct": ct}
    if k:
        quantities["alpha_deg"] = alpha_rad * (180.0 / np.pi)
    return SectionValues(alpha_deg, dl.value(cl_x), dl.value(cd_x), eq, loads["W"], quantities)


def eliminate_phi(values: SectionValues, roots: Roots, sec: Sections) -> dict:
    """Total derivatives at the root (implicit function theorem), scattered to full shape.

    Returns
    -------
    dict
        Quantity -> ndarray (n_points, n_sectors, n_stations, k - 1): column 0 per degree of
        pitch, 1 per m/s of inflow speed, then the effects' columns; zero off the converged
        sections.
    """
    if values.totals is not None:
        return values.totals
    R = values.eq["residual"]
    with np.errstate(all="ignore"):
        dphi = -R.d[:, 1:] / R.d[:, [0]]
    size = int(np.prod(sec.shape))
    out = {}
    for name, q in values.quantities.items():
        d = q.d[:, 1:] + q.d[:, [0]] * dphi
        d[:, 0] *= np.pi / 180.0
        full = np.zeros((size, d.shape[1]))
        full[sec.sel] = np.where(roots.converged[:, None], d, 0.0)
        out[name] = full.reshape(sec.shape + (d.shape[1],))
    return out
