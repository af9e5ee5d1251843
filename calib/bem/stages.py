"""What an effect in the BEM's chain sees and returns, stage by stage.

The native BEM evaluates a chain of effects (:mod:`calib.effects`). Each effect acts on
one *stage*:

``conditions``
    per operating point, before the kinematics: the inflow (:class:`Inflow`: wind speed,
    collective pitch). A conditions effect may read the point's rotor thrust from the
    previous solve (:attr:`PointContext.thrust`); the solver then iterates to a fixed point.
``polar``
    per section, inside the root search: C_L, C_D at the section's α (:class:`PolarState`),
    with the section and its flow in :class:`SectionContext`.
``induction``
    per section, inside the root search: the loss factors of the momentum balance and a
    factor on the blade-element forces (:class:`LossState`).
``loads``
    per section, after the solve: the loads per unit length N', T' (:class:`LoadsState`).

Every quantity may be a plain array or a :class:`calib.bem.dual.Dual` (when the solver
wants exact derivatives); effects write their formulas with the operators and the
functions of :mod:`calib.bem.dual`, so one code path serves both. Nothing here knows
any particular effect (the bem layer never imports :mod:`calib.effects`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from calib.bem import dual as dl

STAGES = ("conditions", "polar", "induction", "loads")
"""Stages in the order the solver applies them."""


@dataclass(frozen=True, eq=False)
class Inflow:
    """Inflow of every operating point (conditions stage).

    Attributes
    ----------
    wind_speed : array or Dual, shape (n_points,)
        Free-stream wind speed the rotor sees [m/s].
    pitch : array or Dual, shape (n_points,)
        Collective blade pitch [deg].
    """

    wind_speed: object
    pitch: object

    def replace(self, **changes) -> "Inflow":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class PointContext:
    """Fixed data of the operating points for conditions-stage effects.

    Attributes
    ----------
    wind_speed, rotor_speed, pitch, air_density : ndarray, shape (n_points,)
        The measured conditions [m/s], [rpm], [deg], [kg/m^3].
    swept_area : float
        Rotor swept area [m^2].
    thrust : array or Dual, shape (n_points,), or None
        Rotor thrust of the previous solve [N] (None on the first pass, and always when no
        effect of the chain reads it).
    """

    wind_speed: np.ndarray
    rotor_speed: np.ndarray
    pitch: np.ndarray
    air_density: np.ndarray
    swept_area: float
    thrust: object = None


@dataclass(frozen=True, eq=False)
class PolarFeatures:
    """Per-station features of the nominal (tabulated) polars, for polar-stage effects.

    Attributes
    ----------
    alpha0_deg : ndarray, shape (n_stations,)
        Zero-lift angle of attack of the linear fit [deg].
    lift_slope : ndarray, shape (n_stations,)
        dC_L/dα of the linear fit [1/rad] (near 0 for cylinders).
    cd0 : ndarray, shape (n_stations,)
        C_D at α0 [-].
    alpha_stall_deg : ndarray, shape (n_stations,)
        Angle of maximum C_L between 0 and 30 deg [deg].
    cl_max : ndarray, shape (n_stations,)
        That maximum [-].

    Notes
    -----
    The linear fit is a least-squares line through C_L(α) on α ∈ [−4, 4] deg (the range
    of the "linear region" in AirfoilPrep's 3-D correction, whose default is [−5, 5] deg).
    """

    alpha0_deg: np.ndarray
    lift_slope: np.ndarray
    cd0: np.ndarray
    alpha_stall_deg: np.ndarray
    cl_max: np.ndarray

    FIT_RANGE_DEG = (-4.0, 4.0)

    @classmethod
    def from_polars(cls, polars) -> "PolarFeatures":
        """From a :class:`calib.bem.polar_grid.SectionPolars` (nodes of its uniform α grid)."""
        a = polars.alpha_grid_deg
        lo, hi = cls.FIT_RANGE_DEG
        fit = (a >= lo) & (a <= hi)
        x = np.radians(a[fit])
        y = polars.cl_nodes[:, fit]
        xm = x.mean()
        slope = ((x - xm) * (y - y.mean(axis=1, keepdims=True))).sum(axis=1) / ((x - xm) ** 2).sum()
        intercept = y.mean(axis=1) - slope * xm
        with np.errstate(all="ignore"):
            alpha0 = np.where(np.abs(slope) > 1e-6, np.degrees(-intercept / slope), 0.0)
        alpha0 = np.clip(alpha0, -20.0, 20.0)
        n_st = polars.cl_nodes.shape[0]
        _, cd0, _, _ = polars.lookup(alpha0, np.arange(n_st))
        attached = (a >= 0.0) & (a <= 30.0)
        k = np.argmax(polars.cl_nodes[:, attached], axis=1)
        return cls(alpha0, slope, cd0, a[attached][k], polars.cl_nodes[:, attached].max(axis=1))


@dataclass(frozen=True, eq=False)
class RotorData:
    """Fixed data of the rotor for section-stage effects.

    Attributes
    ----------
    n_blades : int
    tip_radius, hub_radius, rotor_radius : float
        [m]
    polars : SectionPolars
        The stations' tabulated (nominal) polars.
    reference_reynolds : ndarray, shape (n_stations,), or None
        Reynolds number at which each station's table holds (the rated-speed, design-λ
        chord Reynolds number of :func:`calib.bem.polar_grid.station_reynolds`; None when the
        rotor has no operating schedule).
    kinematic_viscosity : float
        [m^2/s]
    """

    n_blades: int
    tip_radius: float
    hub_radius: float
    rotor_radius: float
    polars: object
    reference_reynolds: np.ndarray | None
    kinematic_viscosity: float

    @cached_property
    def features(self) -> PolarFeatures:
        """:class:`PolarFeatures` of :attr:`polars` (computed on first use)."""
        return PolarFeatures.from_polars(self.polars)


def _take(x, idx):
    return dl.Dual(x.v[idx], x.d[idx]) if isinstance(x, dl.Dual) else x[idx]


def _section_field(name: str, doc: str):
    def get(self):
        values = self._values
        if name not in values:
            values[name] = _take(getattr(self._parent, name), self._idx)
        return values[name]
    return property(get, doc=doc)


class SectionContext:
    """The sections a polar, induction or loads effect acts on (flattened, shape (n,)).

    Parameters
    ----------
    station : ndarray of int
        Blade station index (into ``rotor.features`` arrays).
    r, chord : ndarray
        [m]
    eta : ndarray
        r / R_tip [-].
    twist_deg : ndarray
        Structural twist [deg].
    tip_speed_ratio : array or Dual
        λ = Ω R / V of the section's point, V the inflow speed after the conditions stage and
        R the rotor radius [-].
    reynolds : array or Dual
        Chord Reynolds number of the kinematic inflow, Re = c √(V_x² + V_y²) / ν [-]. The
        induced velocities are left out so that the polar stays a function of α at a given
        point (the root search needs C(α)); at operating tip-speed ratios the in-plane speed
        dominates W and the difference is a few per cent.
    rotor : RotorData

    Notes
    -----
    :meth:`take` returns a view whose fields are gathered on first access (the root search
    takes subsets on every iteration; most effects read one or two fields).
    """

    FIELDS = ("station", "r", "chord", "eta", "twist_deg", "tip_speed_ratio", "reynolds")

    def __init__(self, station, r, chord, eta, twist_deg, tip_speed_ratio, reynolds, rotor: RotorData):
        self._values = dict(station=station, r=r, chord=chord, eta=eta, twist_deg=twist_deg,
                            tip_speed_ratio=tip_speed_ratio, reynolds=reynolds)
        self._parent, self._idx = None, None
        self.rotor = rotor

    station = _section_field("station", "Blade station index [-].")
    r = _section_field("r", "Radius [m].")
    chord = _section_field("chord", "Chord [m].")
    eta = _section_field("eta", "r / R_tip [-].")
    twist_deg = _section_field("twist_deg", "Structural twist [deg].")
    tip_speed_ratio = _section_field("tip_speed_ratio", "λ = Ω R / V [-].")
    reynolds = _section_field("reynolds", "Kinematic chord Reynolds number [-].")

    def take(self, idx) -> "SectionContext":
        """The sections ``idx`` (fields gathered when first read)."""
        view = SectionContext.__new__(SectionContext)
        view._values, view._parent, view._idx, view.rotor = {}, self, idx, self.rotor
        return view


@dataclass(frozen=True, eq=False)
class PolarState:
    """C_L, C_D at the section's angle of attack (polar stage).

    Attributes
    ----------
    alpha_deg : array or Dual
        Angle of attack [deg].
    cl, cd : array or Dual
        Lift and drag coefficients [-].
    """

    alpha_deg: object
    cl: object
    cd: object

    def replace(self, **changes) -> "PolarState":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class LossState:
    """Loss factors of the momentum balance (induction stage).

    The section equations use F = ``tip`` · ``hub`` in the momentum balance and multiply the
    blade-element force coefficients (and so the loads) by ``load``.

    Attributes
    ----------
    phi : array or Dual
        Inflow angle [rad].
    tip, hub : array, Dual or float
        Prandtl's tip and hub loss factors (1 where switched off) [-].
    load : array, Dual or float
        Factor on the section's force coefficients c_n, c_t [-] (1 by default).
    """

    phi: object
    tip: object
    hub: object
    load: object = 1.0

    def replace(self, **changes) -> "LossState":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class LoadsState:
    """Section loads per unit length after the solve (loads stage).

    Attributes
    ----------
    Np, Tp : array or Dual
        Force per unit length normal to the rotor plane and in it (direction of rotation) [N/m].
    """

    Np: object
    Tp: object

    def replace(self, **changes) -> "LoadsState":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class ProbeMap:
    """How an effect with many local parameters reaches its probe columns at each section.

    An effect whose parameters each act on few sections (the correction field: a hat
    function per node) does not seed one derivative column per parameter; it adds *probes*
    (zero-valued seeds) where its parameters enter, and says here how each parameter maps on
    them: ``d q / d p[index[..., m]] += weight[..., m] · d q / d probe[probe[m]]``.

    Attributes
    ----------
    index : ndarray of int, shape (n, m)
        Parameter index within the effect.
    weight : ndarray, shape (n, m)
    probe : ndarray of int, shape (m,)
        Probe of each term.
    """

    index: np.ndarray
    weight: np.ndarray
    probe: np.ndarray = field(default_factory=lambda: np.zeros(0, int))


@dataclass(frozen=True, eq=False)
class CompiledPolar:
    """A polar-stage effect in the form the compiled kernel evaluates (:mod:`calib.bem.kernel`).

    An additive field on tensor-product hat functions of (α, η) followed by a floor on the
    drag, evaluated with the arithmetic of :meth:`calib.corrections.CorrectionGrid.evaluate`
    and :func:`calib.effects.correction_field.floor_drag`. A polar effect that is exactly this
    returns it from an optional ``compiled_polar(theta)``; the root search then runs compiled
    with the effect in it.

    Attributes
    ----------
    alpha_nodes_deg : ndarray, shape (n_alpha,)
        [deg], strictly increasing.
    eta_nodes : ndarray, shape (n_eta,)
        r / R [-], strictly increasing.
    lift, drag : ndarray, shape (n_alpha * n_eta,)
        Nodal ΔC_L, ΔC_D [-], node (i, j) at ``i * n_eta + j``.
    cd_floor : float
        The corrected C_D is held at or above min(``cd_floor``, C_D before the field) [-].
    """

    alpha_nodes_deg: np.ndarray
    eta_nodes: np.ndarray
    lift: np.ndarray
    drag: np.ndarray
    cd_floor: float
