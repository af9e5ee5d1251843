"""Steady lifting-line model of a rigid rotor with a prescribed helical wake: an out-of-method truth.

calib's diagnosis was validated on data from another *BEM* code (CCBlade). This module gives
loads from a vortex method on the same polars, so a misfit between calib's BEM and such data
is a difference of method (no polar change): the diagnosis should not name an effect for it.
Numpy only; it reads rotor definitions and raw polar tables (``benchmarks/export_rotor.py``'s
JSON form) and never calls calib's BEM or effects.

Model
    Each of the B blades is a straight bound vortex line along its pitch axis (no precone,
    tilt, yaw, shear: the battery's ``rigid`` set-up), cut into N panels between the hub
    radius and the tip radius with cosine spacing (fine at root and tip); each panel carries
    a constant circulation Γ_j and its control point lies at the panel's middle in the cosine
    parameter. Trailing vortex filaments of strength Γ_{j-1} − Γ_j leave every panel edge and
    follow a prescribed, non-expanding helix of radius r_edge: x = U_w ψ/Ω, azimuth θ_b − ψ,
    discretised in ψ steps of 2π/``steps_per_revolution``, truncated after
    ``wake_length_diameters`` rotor diameters. The wake is convected at
    U_w = U∞ (1 − ā), ā the area-weighted mean axial induction at the control points; this is
    the mean of the free stream and the far-wake speed U∞ (1 − 2ā), the speed of a vortex
    sheet (Branlard 2017, helical and cylindrical vortex wake models; Okulov & Sørensen 2008).
    ā is iterated (outer loop) until it changes by less than ``wake_tolerance``. The wake
    does not rotate (no a' in the helix) and does not expand.
    Induced velocities at the control points of blade 0 come from the Biot–Savart law for
    straight segments (Katz & Plotkin 2001, ch. 2 and 10) with a Vatistas n = 2 core
    (1/h² → 1/√(r_c⁴ + h⁴), h the distance to the segment's line; Vatistas et al. 1991),
    core radius r_c = ``core_radius_chords`` × the chord at the filament's edge (bound
    segments: the panel's chord); the steady, symmetric rotor has the same Γ on every blade.
    Circulation from the 2-D polars (Kutta–Joukowski): Γ = ½ c W C_L(α), with
    W² = (U∞ + u_x)² + (Ωr − u_θ)², φ = atan2(U∞ + u_x, Ωr − u_θ), α = φ − twist − pitch.
    The nonlinear system Γ − ½ c W C_L = 0 is solved by a few damped fixed-point steps, then
    Newton iteration with a finite-difference Jacobian and back-tracking, falling back to a
    relaxed fixed-point iteration where Newton stalls (kinks of the polar in stall), to
    max |residual| ≤ ``tolerance`` (1e-8) × max |Γ|; the wake speed ā is updated by secant
    steps to |Δā| < ``wake_tolerance`` (2e-5). Every point returns a status and a message.
    Loads: lift L' = ρ W Γ and drag D' = ½ ρ W² c C_D per length; normal (thrust direction)
    F_n = L' cos φ + D' sin φ, tangential F_t = L' sin φ − D' cos φ; thrust B Σ F_n Δr,
    torque B Σ F_t r Δr, power Ω × torque, ``hub_flap_moment`` Σ F_n r Δr (one blade about
    the rotor centre: CCBlade's ``Mb``), ``root_flap_moment`` Σ F_n (r − r_hub) Δr.
Polars
    The raw tables of the rotor (the ones calib reads; one table per airfoil), interpolated
    linearly in α (calib uses PCHIP through the same points). Chord and twist are linear in r
    between the blade stations; at a control point between two stations the coefficients are
    the linear blend in r of the two stations' airfoils at the same α (calib's BEM evaluates
    each station's own airfoil at the station).

Validation (``benchmarks/bench_lifting_line.py``, run of 2026-11-27 with the defaults: 30 panels,
6 D of wake, 36 steps per turn with the first turn 4× finer, core 0.05 c, U_w = U∞(1 − ā))
    Discretisation, NREL 5-MW design point (11.4 m/s, λ = 7.5, 12.96 rpm, pitch 0; P = 5.563 MW,
    T = 782.8 kN, ā = 0.321, 1.9 s on a shared core): panels ×2 ΔP +0.05 %, wake length ×2
    −0.21 %, helix steps ×2 +0.04 %, all three −0.09 % (limit 0.5 %). Physical parameters, not
    discretisation: core 0.01 c −0.76 %, 0.10 c +0.98 %, 0.30 c +2.7 %; wake convected at
    U∞(1 − 0.85 ā) +5.0 %, U∞(1 − ā/2) +13 %, U∞ +21 % (the prescribed wake speed is this
    model's largest uncertainty; U∞(1 − ā) is the one consistent with momentum theory for a
    uniformly loaded rotor: a vortex cylinder of strength BΓ/h with h = 2πU∞(1 − a)/Ω gives
    C_T = 4a(1 − a)).
    NREL UAE Phase VI, sequence H (measured LSS torque): 7 m/s 748 vs 790 N m (−5.3 %), 10 m/s
    1258 vs 1292 N m (−2.6 %); calib's BEM −3.7 % and +0.6 %. 13 m/s (stalled, no rule): −21 %,
    and the stalled solution depends on the iteration path (−33 % with a 4 D wake).
    Lifting line / calib BEM (Prandtl tip and hub loss), NREL 5-MW rigid: at the design point
    power 1.012, thrust 1.014, hub flap moment 1.023; λ = 4 … 10 at pitch 0 (9 rpm) power
    1.007 … 1.018, thrust 1.011 … 1.024, hub flap 1.018 … 1.031; λ = 11 power 0.967; pitch 2 … 8
    deg at λ = 7 and 9.5 power 0.983 … 1.016. calib's BEM without tip and hub loss over with:
    power 1.063, thrust 1.023 at the design point (the reviewer's +6.6 % / +2.8 % look like
    that, or like a wake convected faster than U∞(1 − ā): with U∞(1 − 0.85 ā) this code gives
    LL/BEM power 1.063, thrust 1.037). Time per point 1.1-1.7 s (2-3 s while the 2 cores
    were shared with other jobs).
    Where the difference lives (design point, at the blade stations): tangential force
    LL/BEM 0.96 … 1.02 on r/R 0.25 … 0.8, +3 … +6 % on r/R 0.84 … 0.98 (the lifting line's
    axial induction there 0.35 … 0.38 against the BEM's 0.37 … 0.41 with Prandtl's factor),
    and ±20 % on r/R < 0.2 where the root vortex of the cylinder-to-airfoil transition acts
    (small loads and arms).
Limits
    Steady, rigid, axisymmetric inflow only. In inboard stall (negative lift slope) the
    discrete system has several roots; the one found depends on the start and the wake length
    (a sawtooth in α is possible). Points with ā ≥ :data:`HIGH_INDUCTION` converge but carry a
    ``warning``: the λ = 9.5, pitch −2 deg point of the battery (ā = 0.58) gives 0.74 of the
    BEM's power, where both models are outside their validity.

References
----------
E. Branlard, Wind Turbine Aerodynamics and Vorticity-Based Methods, Springer (2017):
helical and cylindrical vortex wake models, lifting-line methods.
J. Katz, A. Plotkin, Low-Speed Aerodynamics, 2nd ed., Cambridge (2001): straight vortex
segment (ch. 2, and its computational form, ch. 10), lifting-line methods.
G.H. Vatistas, V. Kozel, W.C. Mih, A simpler model for concentrated vortices, Experiments in
Fluids 11 (1991) 73-76.
V.L. Okulov, J.N. Sørensen, Refined Betz limit for rotors with a finite number of blades,
Wind Energy 11 (2008) 415-426.
M.M. Hand et al., Unsteady Aerodynamics Experiment Phase VI: wind tunnel test configurations
and available data campaigns, NREL/TP-500-29955 (2001).

Command line::

    python benchmarks/lifting_line.py point  --wind 11.4 --rpm 12.97 --pitch 0
    python benchmarks/lifting_line.py battery --seeds N --out DIR
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

#: Status of an operating point.
CONVERGED = "converged"
NOT_CONVERGED = "not_converged"
#: Mean axial induction from which a converged point carries a warning (the far wake of
#: momentum theory, U∞ (1 − 2ā), would reverse) [-].
HIGH_INDUCTION = 0.5


# ----------------------------------------------------------------------------- settings and rotor
@dataclass(frozen=True)
class LiftingLineSettings:
    """Discretisation and solver settings.

    Attributes
    ----------
    n_panels : int
        Panels per blade (cosine spacing toward root and tip).
    wake_length_diameters : float
        Length of the helical wake downstream of the rotor [rotor diameters].
    steps_per_revolution : int
        Straight segments per helix turn (ψ step 2π / this).
    near_wake_refinement : int
        The first helix turn has this many times more segments [-].
    core_radius_chords : float
        Vatistas core radius as a fraction of the local chord [-].
    wake_induction_factor : float
        k of the wake convection speed U_w = U∞ (1 − k ā) [-]: 1 (default) the mean of the
        free stream and the far wake; 0 convects the wake with the free stream (a sensitivity
        study, not a model choice), 2 with the far-wake speed.
    tolerance : float
        Circulation residual, relative to max |Γ| [-].
    max_iterations : int
        Newton iterations per wake update.
    max_fixed_point_iterations : int
        Relaxed fixed-point iterations (relaxation 0.1, then 0.03) when Newton did not converge.
    wake_tolerance : float
        Change of the mean axial induction ā that ends the wake iteration [-].
    max_wake_iterations : int
    air_density : float
        [kg/m³]
    """

    n_panels: int = 30
    wake_length_diameters: float = 6.0
    steps_per_revolution: int = 36
    near_wake_refinement: int = 4
    core_radius_chords: float = 0.05
    wake_induction_factor: float = 1.0
    tolerance: float = 1e-8
    max_iterations: int = 30
    max_fixed_point_iterations: int = 4000
    wake_tolerance: float = 2e-5
    max_wake_iterations: int = 30
    air_density: float = 1.225


@dataclass(frozen=True)
class BladeDefinition:
    """Rigid blade and its polars, arrays over the stations.

    Attributes
    ----------
    r, chord, twist_deg : ndarray, shape (n_stations,)
        Station radius [m], chord [m], twist [deg] (positive toward feather).
    hub_radius, tip_radius : float
        [m]
    n_blades : int
    alpha_deg : ndarray, shape (n_alpha,)
        Common angle-of-attack grid of the station tables (the union of the table points) [deg].
    cl, cd : ndarray, shape (n_stations, n_alpha)
        Each station's airfoil table on ``alpha_deg`` (linear interpolation of the raw table).
    name : str
    """

    r: np.ndarray
    chord: np.ndarray
    twist_deg: np.ndarray
    hub_radius: float
    tip_radius: float
    n_blades: int
    alpha_deg: np.ndarray
    cl: np.ndarray
    cd: np.ndarray
    name: str = ""


def blade_from_rotor_dict(rotor: dict) -> BladeDefinition:
    """The blade of a rotor JSON (``export_rotor.rotor_to_dict``): geometry and raw tables.

    Precone, tilt, precurve and presweep are ignored (a rigid straight blade: the battery's
    ``rigid`` set-up). Airfoils must have one table each (no Reynolds-number interpolation).

    Raises
    ------
    ValueError
        For an airfoil with several tables or a table that does not cover ±180 deg.
    """
    tables = []
    for af in rotor["airfoils"]:
        if len(af["tables"]) != 1:
            raise ValueError(f"airfoil {af['name']!r} has {len(af['tables'])} tables; the lifting line "
                             "takes one table per airfoil")
        t = af["tables"][0]
        a = np.asarray(t["alpha_deg"], float)
        if a[0] > -179.5 or a[-1] < 179.5:
            raise ValueError(f"airfoil {af['name']!r} covers {a[0]:g} .. {a[-1]:g} deg; extend it to ±180 deg")
        tables.append((a, np.asarray(t["cl"], float), np.asarray(t["cd"], float)))
    grid = np.unique(np.concatenate([t[0] for t in tables]))
    ids = [int(k) for k in rotor["airfoil_id"]]
    cl = np.array([np.interp(grid, tables[k][0], tables[k][1]) for k in ids])
    cd = np.array([np.interp(grid, tables[k][0], tables[k][2]) for k in ids])
    return BladeDefinition(np.asarray(rotor["r"], float), np.asarray(rotor["chord"], float),
                           np.asarray(rotor["twist_deg"], float), float(rotor["hub_radius"]),
                           float(rotor["tip_radius"]), int(rotor["n_blades"]), grid, cl, cd,
                           str(rotor.get("name", "")))


def load_nrel5mw_rigid() -> dict:
    """calib's embedded NREL 5-MW as a rotor dict, rigid set-up (precone and tilt 0)."""
    sys.path.insert(0, str(HERE))
    from export_rotor import rotor_to_dict  # noqa: PLC0415
    from calib.rotor.library import load_rotor  # noqa: PLC0415
    rotor = load_rotor("nrel5mw")
    return rotor_to_dict(dataclasses.replace(rotor, tilt_deg=0.0, precone_deg=0.0))


# ----------------------------------------------------------------------------- Biot–Savart
def segment_velocity(points, a, b, core_radius) -> np.ndarray:
    """Velocity induced by unit-circulation straight vortex segments a → b at ``points``.

    Parameters
    ----------
    points : ndarray, shape (n_points, 3)
        Evaluation points [m].
    a, b : ndarray, shape (n_segments, 3)
        Start and end of each segment [m] (circulation along a → b, right-hand rule).
    core_radius : ndarray, shape (n_segments,) or float
        Vatistas n = 2 core radius r_c [m] (> 0).

    Returns
    -------
    ndarray, shape (n_points, n_segments, 3)
        Induced velocity per unit circulation [1/m].

    Notes
    -----
    u = Γ/(4π) (r₁ × r₂) / (|r₀|² √(r_c⁴ + h⁴)) · r₀·(r₁/|r₁| − r₂/|r₂|), r₁ = P − A,
    r₂ = P − B, r₀ = B − A, h = |r₁ × r₂| / |r₀| (Katz & Plotkin 2001, ch. 10, with the
    singular 1/h² replaced by Vatistas' n = 2 core 1/√(r_c⁴ + h⁴)). Zero on the segment's line.
    """
    p = np.asarray(points, float)[:, None, :]
    r1 = p - a[None]
    r2 = p - b[None]
    r0 = (b - a)[None]
    cross = np.cross(r1, r2)
    cross2 = np.einsum("...k,...k->...", cross, cross)
    r0sq = np.einsum("...k,...k->...", r0, r0)
    n1 = np.sqrt(np.einsum("...k,...k->...", r1, r1))
    n2 = np.sqrt(np.einsum("...k,...k->...", r2, r2))
    tiny = 1e-12
    dot = np.einsum("...k,...k->...", r0, r1 / np.maximum(n1, tiny)[..., None] - r2 / np.maximum(n2, tiny)[..., None])
    h2 = cross2 / np.maximum(r0sq, tiny)
    rc = np.broadcast_to(np.asarray(core_radius, float), (a.shape[0],))[None]
    k = dot / (4.0 * math.pi * np.maximum(r0sq, tiny) * np.sqrt(rc ** 4 + h2 ** 2))
    return cross * k[..., None]


# ----------------------------------------------------------------------------- discretisation
@dataclass(frozen=True)
class Panels:
    """Panels of one blade: edges (n+1) and control points (n)."""

    edges: np.ndarray
    r: np.ndarray
    dr: np.ndarray
    chord: np.ndarray
    twist_deg: np.ndarray
    edge_chord: np.ndarray
    station: np.ndarray      # (n,) index of the station inboard of each control point
    weight: np.ndarray       # (n,) blend weight of the outboard station


def make_panels(blade: BladeDefinition, n_panels: int) -> Panels:
    """Cosine-spaced panels from hub to tip; control points at the middle in the cosine parameter."""
    s = np.linspace(0.0, 1.0, n_panels + 1)
    span = blade.tip_radius - blade.hub_radius
    edges = blade.hub_radius + span * 0.5 * (1.0 - np.cos(math.pi * s))
    sm = 0.5 * (s[1:] + s[:-1])
    r = blade.hub_radius + span * 0.5 * (1.0 - np.cos(math.pi * sm))
    k = np.clip(np.searchsorted(blade.r, r) - 1, 0, blade.r.size - 2)
    w = np.clip((r - blade.r[k]) / (blade.r[k + 1] - blade.r[k]), 0.0, 1.0)
    return Panels(edges, r, np.diff(edges), np.interp(r, blade.r, blade.chord),
                  np.interp(r, blade.r, blade.twist_deg), np.interp(edges, blade.r, blade.chord), k, w)


def polar_lookup(blade: BladeDefinition, panels: Panels, alpha_deg: np.ndarray):
    """C_L, C_D at each control point's α: the two neighbouring stations' tables blended in r."""
    a = np.mod(np.asarray(alpha_deg, float) + 180.0, 360.0) - 180.0
    g = blade.alpha_deg
    j = np.clip(np.searchsorted(g, a) - 1, 0, g.size - 2)
    t = (a - g[j]) / (g[j + 1] - g[j])
    k, w = panels.station, panels.weight

    def at(tab):
        lo = tab[k, j] + t * (tab[k, j + 1] - tab[k, j])
        hi = tab[k + 1, j] + t * (tab[k + 1, j + 1] - tab[k + 1, j])
        return lo + w * (hi - lo)
    return at(blade.cl), at(blade.cd)


def wake_angles(psi_max: float, steps_per_revolution: int, near_wake_refinement: int) -> np.ndarray:
    """Wake ages ψ of the helix points [rad]: the first turn ``near_wake_refinement`` times finer."""
    d = 2.0 * math.pi / steps_per_revolution
    fine = np.linspace(0.0, 2.0 * math.pi, steps_per_revolution * near_wake_refinement + 1)
    n_far = max(int(math.ceil((psi_max - 2.0 * math.pi) / d)), 0)
    return np.concatenate([fine, 2.0 * math.pi + d * np.arange(1, n_far + 1)])


def influence(blade: BladeDefinition, panels: Panels, settings: LiftingLineSettings, tsr_wake: float,
              rotor_radius: float):
    """Axial and tangential velocity per unit Γ_j at blade 0's control points, all blades summed.

    Parameters
    ----------
    tsr_wake : float
        Ω R / U_w: the helix advances R / tsr_wake per radian [-].
    rotor_radius : float
        R [m].

    Returns
    -------
    ux, ut : ndarray, shape (n_panels, n_panels)
        Induced axial (+ downstream) and tangential (+ direction of rotation) velocity at
        control point i per unit circulation of panel j on every blade [1/m].
    """
    nb = blade.n_blades
    n = panels.r.size
    pitch_per_rad = rotor_radius / tsr_wake
    psi_max = settings.wake_length_diameters * 2.0 * rotor_radius / pitch_per_rad
    psi = wake_angles(psi_max, settings.steps_per_revolution, settings.near_wake_refinement)
    n_steps = psi.size - 1
    cp = np.column_stack([np.zeros(n), panels.r, np.zeros(n)])     # blade 0 along +y
    trail = np.zeros((n, n + 1, 3))
    bound = np.zeros((n, n, 3))
    rc_edge = settings.core_radius_chords * panels.edge_chord
    for b in range(nb):
        th = 2.0 * math.pi * b / nb
        # trailing filaments: (n_edges, n_steps+1, 3)
        ang = np.broadcast_to(th - psi[None, :], (n + 1, psi.size))
        e = panels.edges[:, None]
        pts = np.stack([np.broadcast_to(pitch_per_rad * psi[None, :], ang.shape), e * np.cos(ang),
                        e * np.sin(ang)], axis=-1)
        a = pts[:, :-1].reshape(-1, 3)
        bb = pts[:, 1:].reshape(-1, 3)
        rc = np.repeat(rc_edge, n_steps)
        v = segment_velocity(cp, a, bb, rc).reshape(n, n + 1, n_steps, 3).sum(axis=2)
        trail += v
        # bound vortex segments root -> tip
        d = np.array([0.0, math.cos(th), math.sin(th)])
        a = panels.edges[:-1, None] * d
        bb = panels.edges[1:, None] * d
        bound += segment_velocity(cp, a, bb, settings.core_radius_chords * panels.chord)
    m = bound + trail[:, 1:] - trail[:, :-1]
    # blade 0 at θ = 0: e_x axial, e_θ = (0, 0, 1) at points (0, r, 0) for rotation about +x
    return m[..., 0], m[..., 2]


# ----------------------------------------------------------------------------- one operating point
@dataclass(frozen=True)
class PointResult:
    """Loads of one operating point (SI units) and the solver's state."""

    power: float
    thrust: float
    torque: float
    hub_flap_moment: float
    root_flap_moment: float
    r: np.ndarray                 # control points [m]
    fn: np.ndarray                # normal force per length at the control points [N/m]
    ft: np.ndarray                # tangential force per length [N/m]
    gamma: np.ndarray             # circulation [m²/s]
    alpha_deg: np.ndarray
    axial_induction: np.ndarray   # −u_x / U∞ at the control points [-]
    mean_axial_induction: float   # ā of the wake convection [-]
    iterations: int               # Newton iterations, summed over the wake updates
    wake_iterations: int
    status: str
    message: str
    seconds: float
    warning: str = ""             # e.g. ā ≥ 0.5: a converged point outside the helix model's validity


def _sections(blade, panels, gamma, ux, ut, wind, omega, pitch_deg):
    vx = wind + ux @ gamma
    vt = omega * panels.r - ut @ gamma
    phi = np.arctan2(vx, vt)
    alpha = np.degrees(phi) - panels.twist_deg - pitch_deg
    cl, cd = polar_lookup(blade, panels, alpha)
    w = np.hypot(vx, vt)
    return vx, vt, phi, alpha, cl, cd, w


def solve_circulation(blade, panels, ux, ut, wind, omega, pitch_deg, gamma0, settings):
    """Γ with Γ = ½ c W C_L(α(Γ)) for fixed influence matrices.

    Returns
    -------
    gamma : ndarray
    iterations : int
    ok : bool
    residual : float
        max |Γ − ½ c W C_L| / max |Γ| at the end [-].
    """
    def residual(g):
        *_, cl, _, w = _sections(blade, panels, g, ux, ut, wind, omega, pitch_deg)
        return g - 0.5 * panels.chord * w * cl

    g = np.array(gamma0, float)
    # a few damped fixed-point steps give Newton a start in the right basin
    for _ in range(10):
        g = g - 0.3 * residual(g)
    scale = max(float(np.max(np.abs(g))), 1e-9)
    res = residual(g)
    n = g.size
    for it in range(1, settings.max_iterations + 1):
        err = float(np.max(np.abs(res))) / scale
        if err <= settings.tolerance:
            return g, it - 1, True, err
        h = 1e-6 * scale
        jac = np.empty((n, n))
        for j in range(n):
            gj = g.copy()
            gj[j] += h
            jac[:, j] = (residual(gj) - res) / h
        try:
            step = -np.linalg.solve(jac, res)
        except np.linalg.LinAlgError:
            step = -0.3 * res
        lam = 1.0
        norm0 = float(np.linalg.norm(res))
        while lam > 1.0 / 64:
            trial = g + lam * step
            rt = residual(trial)
            if np.linalg.norm(rt) < (1.0 - 1e-4 * lam) * norm0:
                break
            lam *= 0.5
        else:   # no descent: a damped fixed-point step instead
            trial = g - 0.2 * res
            rt = residual(trial)
        g, res = trial, rt
        scale = max(float(np.max(np.abs(g))), 1e-9)
    # Newton stalls where the piecewise-linear polar has kinks and negative slopes (inboard
    # stall); the relaxed fixed-point iteration then converges (checked at λ = 5, 9 rpm)
    n_it = settings.max_iterations
    for relax in (0.1, 0.03):
        for k in range(settings.max_fixed_point_iterations):
            res = residual(g)
            scale = max(float(np.max(np.abs(g))), 1e-9)
            if float(np.max(np.abs(res))) / scale <= settings.tolerance:
                return g, n_it + k, True, float(np.max(np.abs(res))) / scale
            g = g - relax * res
        n_it += settings.max_fixed_point_iterations
    res = residual(g)
    err = float(np.max(np.abs(res))) / max(float(np.max(np.abs(g))), 1e-9)
    return g, n_it, err <= settings.tolerance, err


def solve_point(blade: BladeDefinition, wind_speed: float, rotor_speed_rpm: float, pitch_deg: float,
                settings: LiftingLineSettings = LiftingLineSettings(), rotor_radius: float | None = None,
                panels: Panels | None = None) -> PointResult:
    """Steady lifting-line solution of one operating point.

    Parameters
    ----------
    blade : BladeDefinition
    wind_speed : float
        U∞ [m/s].
    rotor_speed_rpm : float
        [rpm]
    pitch_deg : float
        Blade pitch [deg] (positive toward feather).
    settings : LiftingLineSettings
    rotor_radius : float, optional
        R of the wake length [m] (default the tip radius).

    Returns
    -------
    PointResult
        ``status`` is ``"converged"`` only when both the circulation (``tolerance``) and the
        wake convection speed (``wake_tolerance``) settled; otherwise ``"not_converged"``
        with the reason in ``message`` (the loads are those of the last iterate).
    """
    t0 = time.perf_counter()
    R = float(rotor_radius or blade.tip_radius)
    panels = panels or make_panels(blade, settings.n_panels)
    omega = rotor_speed_rpm * math.pi / 30.0
    U = float(wind_speed)
    rho = settings.air_density
    area_w = panels.r * panels.dr
    # start: wake pitch of ā = 0.25 and Γ from the inflow with that induction, no swirl
    a_mean = 0.25
    gamma = None
    total_it, ok_inner, wake_ok = 0, False, False
    prev = None
    floor = False
    for wit in range(1, settings.max_wake_iterations + 1):
        u_w = U * (1.0 - settings.wake_induction_factor * a_mean)
        floor = u_w < 0.3 * U
        u_w = max(u_w, 0.3 * U)
        ux, ut = influence(blade, panels, settings, omega * R / u_w, R)
        if gamma is None:
            vx, vt = U * (1.0 - a_mean) * np.ones_like(panels.r), omega * panels.r
            alpha = np.degrees(np.arctan2(vx, vt)) - panels.twist_deg - pitch_deg
            cl, _ = polar_lookup(blade, panels, alpha)
            gamma = 0.5 * panels.chord * np.hypot(vx, vt) * cl
        gamma, it, ok_inner, err = solve_circulation(blade, panels, ux, ut, U, omega, pitch_deg, gamma, settings)
        total_it += it
        a_new = float(np.sum(-(ux @ gamma) / U * area_w) / np.sum(area_w))
        change = abs(a_new - a_mean)
        # secant step on g(ā) = F(ā) − ā (F: the mean induction the wake of pitch ā gives)
        g_now = a_new - a_mean
        if prev is not None and abs(g_now - prev[1]) > 1e-12:
            slope = (g_now - prev[1]) / (a_mean - prev[0])
            a_next = a_mean - g_now / slope if slope < -0.05 else a_new
        else:
            a_next = a_new
        prev = (a_mean, g_now)
        a_mean = float(np.clip(a_next, -0.2, 0.6))
        if change < settings.wake_tolerance:
            wake_ok = True
            break
    problems = []
    if not ok_inner:
        problems.append(f"circulation residual {err:.2e} > tolerance {settings.tolerance:g} after {it} Newton "
                        "iterations")
    if not wake_ok:
        problems.append(f"wake speed still changing (Δā = {change:.2e}) after {wit} updates")
    if floor:
        problems.append(f"wake speed held at its floor 0.3 U∞ (ā = {a_mean:.3f}, factor "
                        f"{settings.wake_induction_factor:g}): no consistent helix")
    big = float(np.max(np.abs(gamma)))
    if big > 0 and gamma[-1] * gamma[np.argmax(np.abs(gamma))] < -1e-3 * big * big:
        problems.append("tip-panel circulation of opposite sign to the blade's: a spurious root (core radius "
                        "too small for the tip panels)")
    msg = "; ".join(problems)
    # Loads with the final Γ (and the wake of the last update: within wake_tolerance of ā)
    vx, vt, phi, alpha, cl, cd, w = _sections(blade, panels, gamma, ux, ut, U, omega, pitch_deg)
    lift = rho * w * gamma
    drag = 0.5 * rho * w * w * panels.chord * cd
    fn = lift * np.cos(phi) + drag * np.sin(phi)
    ft = lift * np.sin(phi) - drag * np.cos(phi)
    B = blade.n_blades
    torque = B * float(np.sum(ft * panels.r * panels.dr))
    status = NOT_CONVERGED if problems else CONVERGED
    warning = ""
    if a_mean >= HIGH_INDUCTION:
        warning = (f"mean axial induction {a_mean:.3f} >= {HIGH_INDUCTION:g}: the far wake U(1 - 2a) would reverse "
                   "(turbulent-wake state); a helix convected at U(1 - a) is outside its validity here, as is "
                   "momentum theory without an empirical high-thrust correction")
    return PointResult(power=omega * torque, thrust=B * float(np.sum(fn * panels.dr)), torque=torque,
                       hub_flap_moment=float(np.sum(fn * panels.r * panels.dr)),
                       root_flap_moment=float(np.sum(fn * (panels.r - blade.hub_radius) * panels.dr)),
                       r=panels.r, fn=fn, ft=ft, gamma=gamma, alpha_deg=alpha,
                       axial_induction=-(ux @ gamma) / U, mean_axial_induction=a_mean, iterations=total_it,
                       wake_iterations=wit, status=status, message=msg or "ok", warning=warning,
                       seconds=time.perf_counter() - t0)


def at_stations(blade: BladeDefinition, res: PointResult, values: np.ndarray) -> np.ndarray:
    """Spanwise values at the blade stations (linear in r; zero at stations on the hub or tip)."""
    out = np.interp(blade.r, res.r, values)
    out[(blade.r <= blade.hub_radius + 1e-9) | (blade.r >= blade.tip_radius - 1e-9)] = 0.0
    return out


def solve_points(blade: BladeDefinition, wind_speed, rotor_speed_rpm, pitch_deg,
                 settings: LiftingLineSettings = LiftingLineSettings(), rotor_radius: float | None = None,
                 say=None) -> dict:
    """Lifting-line loads of several operating points.

    Returns
    -------
    dict
        Lists over the points: ``power`` [W], ``thrust`` [N], ``torque`` [N m],
        ``hub_flap_moment``, ``root_flap_moment`` [N m], ``fn_stations``, ``ft_stations``
        (per point, at the blade stations ``r_stations``) [N/m], ``iterations``,
        ``wake_iterations``, ``status``, ``message``, ``warning`` (non-empty for ā ≥
        :data:`HIGH_INDUCTION`), ``seconds``, ``mean_axial_induction``.
    """
    panels = make_panels(blade, settings.n_panels)
    keys = ("power", "thrust", "torque", "hub_flap_moment", "root_flap_moment", "iterations",
            "wake_iterations", "status", "message", "warning", "seconds", "mean_axial_induction")
    out = {k: [] for k in keys}
    out["fn_stations"], out["ft_stations"], out["r_stations"] = [], [], blade.r.tolist()
    for k, (v, n, p) in enumerate(zip(np.atleast_1d(wind_speed), np.atleast_1d(rotor_speed_rpm),
                                      np.atleast_1d(pitch_deg))):
        res = solve_point(blade, float(v), float(n), float(p), settings, rotor_radius, panels)
        for key in keys:
            out[key].append(getattr(res, key))
        out["fn_stations"].append(at_stations(blade, res, res.fn).tolist())
        out["ft_stations"].append(at_stations(blade, res, res.ft).tolist())
        if say:
            say(f"  point {k}: V={v:.2f} m/s, {n:.2f} rpm, pitch {p:g}: P={res.power / 1e3:.1f} kW, "
                f"T={res.thrust / 1e3:.1f} kN, {res.status} ({res.seconds:.2f} s)")
    return out


# ----------------------------------------------------------------------------- battery data
def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    q = sub.add_parser("point", help="one operating point of the NREL 5-MW (rigid)")
    q.add_argument("--wind", type=float, default=11.4)
    q.add_argument("--rpm", type=float, default=None, help="default: from --tsr")
    q.add_argument("--tsr", type=float, default=7.5)
    q.add_argument("--pitch", type=float, default=0.0)
    q.add_argument("--panels", type=int, default=LiftingLineSettings.n_panels)
    bq = sub.add_parser("battery", help="noisy CSVs of the rigid set-up's operating points")
    bq.add_argument("--seeds", type=int, default=20, help="noise copies per data set (seeds 26000 + k)")
    bq.add_argument("--out", type=Path, default=ROOT / "bench_output" / "lifting_line_battery",
                    help="folder of data/rigid/*.csv, config_rigid.toml and truth_rigid.json")
    bq.add_argument("--data-sets", nargs="*", default=None,
                    help="control, leading_edge_erosion, uniform_table, rotational_augmentation (default all)")
    bq.add_argument("--wake-induction-factor", type=float, default=LiftingLineSettings.wake_induction_factor,
                    help="k of the wake speed U(1 - k a); other than 1 only for a sensitivity study")
    args = p.parse_args(argv)
    if args.command == "point":
        rotor = load_nrel5mw_rigid()
        blade = blade_from_rotor_dict(rotor)
        R = float(rotor["rotor_radius"])
        rpm = args.rpm if args.rpm is not None else args.tsr * args.wind / R * 30.0 / math.pi
        res = solve_point(blade, args.wind, rpm, args.pitch,
                          dataclasses.replace(LiftingLineSettings(), n_panels=args.panels), R)
        print(json.dumps({k: getattr(res, k) for k in ("power", "thrust", "torque", "hub_flap_moment",
                                                         "root_flap_moment", "mean_axial_induction", "iterations",
                                                         "wake_iterations", "status", "message", "warning", "seconds")},
                         indent=1))
        return 0
    from lifting_line_battery import write_battery  # noqa: PLC0415
    write_battery(args.seeds, args.out, args.data_sets,
                  settings=LiftingLineSettings(wake_induction_factor=args.wake_induction_factor))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    sys.exit(main())
