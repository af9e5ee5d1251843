"""The battery's hidden effects, written in CCBlade's world (runs in ``.bench-venv``).

Every form here differs on purpose from the corresponding model of ``calib.effects`` (the
diagnosis fits those; truths of another form test whether it still names the physics):

``correction3D`` (rotational augmentation)
    WISDEM's ``Polar.correction3D`` applied to each station's table before CCAirfoil is
    built: Du & Selig's (1998) lift factor with a = b = d = 1, Eggers' (2003) drag increment,
    the lift correction clipped to ±0.25, WISDEM's own linear-region fit and its piecewise-
    linear 25-45 deg blending, at one tip-speed ratio (the design value, as 3-D polars are
    made once for a rotor). calib: Snel, Du-Selig (with a drag *decrease*) or Chaviaropoulos-
    Hansen with a free strength, the tip-speed ratio of each point, a C¹ blending, no clip.
``reynolds`` (Reynolds-number effect following each section's Re)
    CCBlade computes each section's Reynolds number Re = ρ W c / μ at each point; the
    airfoil seen at that Re is the table with (:func:`reynolds_change`) the skin-friction
    part of the drag scaled like a turbulent flat plate, C_f ∝ Re^(−1/5) (Schlichting &
    Gersten 2017), i.e. ΔC_D = C_D,min [(Re/Re_ref)^(−0.2) − 1] added at every angle, and
    C_L,max lowered by :data:`CLMAX_PER_DECADE` per decade of Re below the section's Re_ref
    (Abbott & von Doenhoff 1959 show C_L,max rising with Re), ramped in linearly over the
    6 deg below the stall angle. Re_ref of each section: its chord and relative speed at a
    representative operating point (:func:`reference_reynolds`: rated 12.1 rpm at the design
    tip-speed ratio 7.55, Betz induction 1/3, Jonkman et al. 2009), times
    :data:`RE_REF_FACTOR`. calib: C_D multiplied by (Re_ref/Re)^n in attached flow only, lift
    multiplied by (1 − k ln(Re_ref/Re)) with C¹ weights, Re_ref from the rotor's schedule.
``uniform`` (polars at another Reynolds number, every section alike)
    The change of ``reynolds`` at one fixed ratio Re/Re_ref = :data:`UNIFORM_RE_RATIO` for
    every station and operating point: a table change that does not follow the flow.
``erosion`` (leading-edge erosion)
    Damage ramping linearly from r/R = :data:`EROSION_START` to full at the tip (calib: a
    smoothstep of width 0.1 from a free onset): a drag rise :data:`EROSION_DRAG_RISE` × ramp
    at every angle and a loss of lift *slope*, C_L scaled by (1 − :data:`EROSION_SLOPE_LOSS`
    × ramp) for |α| <= 15 deg fading linearly to none at 30 deg (calib: lift lost only near
    stall, drag only in attached flow). Sareen, Sapre & Selig (2014) measured both a drag
    rise and a lift-slope loss on eroded sections.
``blockage`` (closed wind-tunnel test section)
    The rotor in a closed test section of area ratio ε = A/C = :data:`BLOCKAGE_AREA_RATIO`:
    the free-stream speed U_F of unbounded flow that gives the same thrust and disc speed
    follows from the momentum, continuity and Bernoulli equations of the rotor stream tube
    and the bypass flow between it and the walls, solved exactly (:func:`blockage_speed_ratio`;
    the model of Glauert 1933 as worked out by Barnsley & Wellicome 1990 and Bahaj et al. 2007,
    compared with actuator-disc computations by Mikkelsen & Sørensen 2002), and iterated with
    CCBlade's own thrust at U_F until U_F settles. calib: the first-order closed form
    V'/V = 1 + (ε/4) C_T/√(1 − C_T), continued linearly above C_T = 0.8.

References
----------
Z. Du, M.S. Selig, A 3-D stall-delay model for horizontal axis wind turbine performance
prediction, AIAA-98-0021 (1998).
F.A. Eggers, R.E. Digumarthi, Assessment of approximate 3D correction for rotating airfoil
data using test data, ASME Wind Energy Symposium (2003) (as implemented in WISDEM's Polar).
WISDEM 4.2.9, ``wisdem.ccblade.Polar.correction3D`` (NREL), https://github.com/WISDEM/WISDEM.
H. Schlichting, K. Gersten, Boundary-Layer Theory, 9th ed., Springer (2017), turbulent skin friction.
I.H. Abbott, A.E. von Doenhoff, Theory of Wing Sections, Dover (1959), Re dependence of C_L,max.
J. Jonkman, S. Butterfield, W. Musial, G. Scott, Definition of a 5-MW reference wind turbine,
NREL/TP-500-38060 (2009): rated rotor speed 12.1 rpm, optimal tip-speed ratio 7.55.
A. Sareen, C.A. Sapre, M.S. Selig, Effects of leading edge erosion on wind turbine blade
performance, Wind Energy 17 (2014) 1531-1542.
H. Glauert, Wind tunnel interference on wings, bodies and airscrews, ARC R&M 1566 (1933).
M.J. Barnsley, J.F. Wellicome, Final report on the 2nd phase of development and testing of a
horizontal axis wind turbine test rig for the investigation of stall regulation aerodynamics,
ETSU WN 5113 (1990).
A.S. Bahaj, A.F. Molland, J.R. Chaplin, W.M.J. Batten, Power and thrust measurements of marine
current turbines under various hydrodynamic flow conditions in a cavitation tunnel and a
towing tank, Renewable Energy 32 (2007) 407-426.
R. Mikkelsen, J.N. Sørensen, Modelling of wind tunnel blockage, Global Windpower Conference,
Paris (2002).
"""

from __future__ import annotations

import copy
import math
import sys
import types

import numpy as np

#: Design tip-speed ratio of the NREL 5-MW (Jonkman et al. 2009) at which the 3-D polars are made [-].
DESIGN_TSR = 7.55
#: Rated rotor speed of the NREL 5-MW (Jonkman et al. 2009) [rpm].
RATED_RPM = 12.1
#: Axial induction at the representative point of :func:`reference_reynolds` (Betz optimum) [-].
REFERENCE_INDUCTION = 1.0 / 3.0
#: Re_ref = this factor times the section's Reynolds number at the representative point [-].
RE_REF_FACTOR = 1.0
#: Exponent of the skin-friction drag, C_f ∝ Re^(−1/5) (turbulent flat plate) [-].
FRICTION_EXPONENT = 0.2
#: C_L,max loss per decade of Reynolds number below Re_ref [-].
CLMAX_PER_DECADE = 0.4
#: Width of the linear ramp of the C_L,max loss below the stall angle [deg].
CLMAX_RAMP_DEG = 6.0
#: Re/Re_ref of the uniform table change (every section and point) [-].
UNIFORM_RE_RATIO = 0.5
#: Span r/R where the erosion ramp starts; full damage at the tip [-].
EROSION_START = 0.6
#: Drag-coefficient rise at the tip [-].
EROSION_DRAG_RISE = 0.010
#: Relative lift-slope loss at the tip [-].
EROSION_SLOPE_LOSS = 0.10
#: Swept area over tunnel cross-section of the blockage data set [-].
BLOCKAGE_AREA_RATIO = 0.10

PARAMETERS = {k: v for k, v in dict(globals()).items() if k.isupper()}


# ----------------------------------------------------------------------------- WISDEM's Polar
def import_polar():
    """WISDEM's ``Polar`` class (``wisdem.ccblade.Polar``) without pandas.

    ``Polar.py`` imports ``polar_file`` (which needs pandas) only to read polar files; the
    minimal ``.bench-venv`` has no pandas and nothing here reads files, so when pandas is
    missing a stand-in ``wisdem.ccblade.polar_file`` whose reader refuses is registered
    first (``import_ccblade`` of ``ccblade_runner.py`` must have run).
    """
    import importlib.util  # noqa: PLC0415

    if importlib.util.find_spec("pandas") is None:
        if "wisdem.ccblade.polar_file" not in sys.modules:
            stub = types.ModuleType("wisdem.ccblade.polar_file")

            def loadPolarFile(*args, **kwargs):  # noqa: N802  (the name WISDEM imports)
                raise NotImplementedError("reading polar files needs pandas (not in .bench-venv)")
            stub.loadPolarFile = loadPolarFile
            sys.modules["wisdem.ccblade.polar_file"] = stub
    from wisdem.ccblade.Polar import Polar  # noqa: PLC0415
    return Polar


# ----------------------------------------------------------------------------- per-station tables
def is_lifting(cl) -> bool:
    """Whether a table lifts (cylinders have C_L = 0 and get no polar effect)."""
    return float(np.max(np.abs(cl))) > 0.01


def stall_angle(alpha_deg, cl) -> float:
    """Angle of the largest C_L on 0 … 30 deg, clipped to 5 … 20 deg [deg]."""
    a, c = np.asarray(alpha_deg, float), np.asarray(cl, float)
    win = (a >= 0.0) & (a <= 30.0)
    return float(np.clip(a[win][np.argmax(c[win])], 5.0, 20.0))


def minimum_drag(alpha_deg, cd) -> float:
    """Smallest C_D on −10 … 10 deg (the skin-friction drag of attached flow) [-]."""
    a, c = np.asarray(alpha_deg, float), np.asarray(cd, float)
    return float(np.min(c[(a >= -10.0) & (a <= 10.0)]))


def per_station(rotor: dict, change) -> dict:
    """A copy of ``rotor`` with one airfoil per station, each table changed by ``change``.

    Parameters
    ----------
    rotor : dict
        Rotor JSON of ``export_rotor.py``.
    change : callable(alpha_deg, cl, cd, k) -> (cl, cd)
        New coefficients of station ``k``'s table (arrays over ``alpha_deg``).
    """
    out = copy.deepcopy(rotor)
    airfoils = []
    for k, af_id in enumerate(rotor["airfoil_id"]):
        src = rotor["airfoils"][int(af_id)]
        tables = []
        for t in src["tables"]:
            cl, cd = change(np.asarray(t["alpha_deg"], float), np.asarray(t["cl"], float),
                            np.asarray(t["cd"], float), k)
            tables.append({**t, "cl": [float(x) for x in cl], "cd": [float(x) for x in cd]})
        airfoils.append({"name": f"{src['name']}@{k}", "tables": tables})
    out["airfoils"], out["airfoil_id"] = airfoils, list(range(len(rotor["airfoil_id"])))
    return out


# ----------------------------------------------------------------------------- (a) rotational augmentation
def correction3d_rotor(rotor: dict, tsr: float = DESIGN_TSR) -> dict:
    """Each station's polar through WISDEM's ``Polar.correction3D`` (Du-Selig lift, Eggers drag).

    Parameters
    ----------
    rotor : dict
        Rotor JSON (``export_rotor.py``).
    tsr : float
        Tip-speed ratio of the correction [-] (default the design value :data:`DESIGN_TSR`).

    Notes
    -----
    ``correction3D(r/R, c/r, tsr, lift_method="DuSelig", drag_method="Eggers")`` with its
    defaults (``max_cl_corr`` 0.25, ``blending_method`` ``"linear_25_45"``); R is the tip
    radius. Cylinders (no lift) and the hub and tip stations (no load) are left unchanged.
    """
    polar_cls = import_polar()
    r, chord = np.asarray(rotor["r"], float), np.asarray(rotor["chord"], float)
    hub, tip = float(rotor["hub_radius"]), float(rotor["tip_radius"])

    def change(alpha, cl, cd, k):
        if not is_lifting(cl) or not hub < r[k] < tip:
            return cl, cd
        p = polar_cls(alpha=alpha, cl=cl, cd=cd, cm=np.zeros_like(alpha), Re=None, radians=False)
        q = p.correction3D(r[k] / tip, chord[k] / r[k], tsr, lift_method="DuSelig", drag_method="Eggers")
        return np.asarray(q.cl, float), np.asarray(q.cd, float)
    return per_station(rotor, change)


# ----------------------------------------------------------------------------- (b), (c) Reynolds number
def reynolds_change(alpha_deg, cl, cd, ratio: float, cd_min: float, alpha_stall: float):
    """Coefficients at Reynolds number ``ratio`` × Re_ref of a table that holds at Re_ref.

    Parameters
    ----------
    alpha_deg : float or ndarray
        Angle of attack [deg].
    cl, cd : float or ndarray
        The table's coefficients at ``alpha_deg`` [-].
    ratio : float
        Re / Re_ref [-].
    cd_min : float
        The table's skin-friction drag (:func:`minimum_drag`) [-].
    alpha_stall : float
        The table's stall angle (:func:`stall_angle`) [deg].

    Returns
    -------
    cl, cd
        ``cd + cd_min ((Re/Re_ref)^(−0.2) − 1)`` and ``cl − 0.4 log10(Re_ref/Re) s(α)``, s
        rising linearly from 0 at α_s − 6 deg to 1 at α_s, 1 up to max(α_s + 5, 20) deg and
        falling linearly to 0 at 30 deg (fully separated flow hardly depends on Re).
    """
    ratio = max(float(ratio), 1e-6)
    d_cd = cd_min * (ratio ** (-FRICTION_EXPONENT) - 1.0)
    loss = CLMAX_PER_DECADE * math.log10(1.0 / ratio)
    hold = max(alpha_stall + 5.0, 20.0)
    s = np.interp(alpha_deg, [alpha_stall - CLMAX_RAMP_DEG, alpha_stall, hold, 30.0], [0.0, 1.0, 1.0, 0.0])
    return cl - loss * s, cd + d_cd


def reference_reynolds(r, chord, tip_radius: float, nu: float) -> np.ndarray:
    """Each section's Re_ref: its Reynolds number at the representative operating point.

    Parameters
    ----------
    r, chord : ndarray
        Station radius and chord [m].
    tip_radius : float
        [m]
    nu : float
        Kinematic viscosity μ/ρ [m²/s] (CCBlade's μ and ρ).

    Notes
    -----
    Rated rotor speed Ω = :data:`RATED_RPM`, wind speed V = Ω R / :data:`DESIGN_TSR`, axial
    induction 1/3 and no tangential induction: W = √((Ω r)² + (V (1 − 1/3))²) and
    Re_ref = :data:`RE_REF_FACTOR` × W c / ν.
    """
    omega = RATED_RPM * math.pi / 30.0
    v = omega * tip_radius / DESIGN_TSR
    w = np.sqrt((omega * np.asarray(r, float)) ** 2 + (v * (1.0 - REFERENCE_INDUCTION)) ** 2)
    return RE_REF_FACTOR * w * np.asarray(chord, float) / nu


class ReynoldsAirfoil:
    """A CCAirfoil seen at the section's actual Reynolds number (:func:`reynolds_change`).

    CCBlade calls ``evaluate(alpha [rad], Re)`` with the Re it computed for the section
    (ρ W c / μ); this wrapper applies the change for ``Re / re_ref`` to the wrapped
    airfoil's coefficients (the same smoothing spline the control uses, so nothing else
    changes). Only ``evaluate`` is provided: CCBlade runs without derivatives here.
    """

    def __init__(self, base, re_ref: float, cd_min: float, alpha_stall: float):
        self.base, self.re_ref, self.cd_min, self.alpha_stall = base, float(re_ref), cd_min, alpha_stall
        self.ratio_range = [math.inf, -math.inf]     # smallest and largest Re/Re_ref seen

    def evaluate(self, alpha, re, return_cm=False):
        cl, cd = self.base.evaluate(alpha, re)
        ratio = float(re) / self.re_ref
        self.ratio_range = [min(self.ratio_range[0], ratio), max(self.ratio_range[1], ratio)]
        cl, cd = reynolds_change(math.degrees(float(alpha)), cl, cd, ratio, self.cd_min, self.alpha_stall)
        return float(cl), float(cd)


def uniform_rotor(rotor: dict, ratio: float = UNIFORM_RE_RATIO) -> dict:
    """Every lifting station's table changed as at Re/Re_ref = ``ratio`` (one table change for all)."""
    def change(alpha, cl, cd, k):
        if not is_lifting(cl):
            return cl, cd
        return reynolds_change(alpha, cl, cd, ratio, minimum_drag(alpha, cd), stall_angle(alpha, cl))
    return per_station(rotor, change)


# ----------------------------------------------------------------------------- (d) erosion
def erosion_ramp(eta) -> np.ndarray:
    """Damage fraction: 0 inboard of r/R = :data:`EROSION_START`, rising linearly to 1 at the tip [-]."""
    return np.clip((np.asarray(eta, float) - EROSION_START) / (1.0 - EROSION_START), 0.0, 1.0)


def erosion_rotor(rotor: dict) -> dict:
    """Each station's table with the drag rise and lift-slope loss of its erosion ramp (r/R on the tip radius)."""
    eta = np.asarray(rotor["r"], float) / float(rotor["tip_radius"])

    def change(alpha, cl, cd, k):
        ramp = float(erosion_ramp(eta[k]))
        if ramp == 0.0 or not is_lifting(cl):
            return cl, cd
        h = np.interp(np.abs(alpha), [0.0, 15.0, 30.0], [1.0, 1.0, 0.0])
        return cl * (1.0 - EROSION_SLOPE_LOSS * ramp * h), cd + EROSION_DRAG_RISE * ramp
    return per_station(rotor, change)


# ----------------------------------------------------------------------------- (e) blockage
def blockage_speed_ratio(ct: float, area_ratio: float) -> float:
    """U_F / U_T of a rotor with thrust coefficient ``ct`` in a closed test section.

    Parameters
    ----------
    ct : float
        Thrust coefficient on the tunnel speed, C_T = T / (½ ρ A U_T²) [-].
    area_ratio : float
        Swept area over tunnel cross-section, ε = A/C [-].

    Returns
    -------
    float
        Equivalent free-stream speed over tunnel speed [-].

    Notes
    -----
    Speeds on U_T: x₁ in the far wake (area A₁), x₂ in the bypass flow between wake and
    walls, x_t at the disc; σ = A₁/C. With the thrust T = ½ρA(u₂² − u₁²) (the pressure jump
    across the disc, Bernoulli up- and downstream of it), the wake and bypass at one static
    pressure p₂ and p₀ − p₂ = ½ρ(u₂² − U_T²) (Bernoulli in the bypass):

    - thrust: C_T = x₂² − x₁²;
    - continuity: 1 = σ x₁ + (1 − σ) x₂, and at the disc ε x_t = σ x₁;
    - axial momentum over the test section: ½(x₂² − 1) − ½ ε C_T = σ x₁² + (1 − σ) x₂² − 1.

    x₂ > 1 is found by bracketing and bisection (``scipy.optimize.brentq``), then x_t; the
    unbounded flow with the same disc speed and thrust has U_F = u_t + T / (2 ρ A u_t)
    (actuator-disc momentum), i.e. U_F/U_T = x_t + C_T / (4 x_t). As ε → 0 this tends to 1,
    and to first order in ε it is Glauert's 1 + (ε/4) C_T/√(1 − C_T).
    """
    from scipy.optimize import brentq  # noqa: PLC0415

    ct, eps = float(ct), float(area_ratio)
    if eps <= 0.0 or ct <= 0.0:
        return 1.0

    def parts(x2):
        x1 = math.sqrt(max(x2 * x2 - ct, 0.0))
        sigma = (x2 - 1.0) / (x2 - x1)
        return x1, sigma

    def residual(x2):
        x1, sigma = parts(x2)
        return 0.5 * (x2 * x2 - 1.0) - 0.5 * eps * ct - (sigma * x1 * x1 + (1.0 - sigma) * x2 * x2 - 1.0)

    lo = max(1.0, math.sqrt(ct)) + 1e-12
    hi = lo + 1.0
    while residual(hi) * residual(lo) > 0.0:
        hi = 1.0 + 2.0 * (hi - 1.0)
        if hi > 1e3:
            raise ValueError(f"no momentum solution for C_T = {ct:g}, area ratio {eps:g}")
    x2 = brentq(residual, lo, hi, xtol=1e-15, rtol=1e-15)
    x1, sigma = parts(x2)
    xt = sigma * x1 / eps
    return xt + ct / (4.0 * xt)
