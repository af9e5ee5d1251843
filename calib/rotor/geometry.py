"""Rotor geometry: blade stations, hub and tip radius, blade count, orientation."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.errors import InputError
from calib.rotor.polar import Airfoil


@dataclass(frozen=True, eq=False)
class OperatingSchedule:
    """Steady control schedule of a variable-speed, pitch-regulated turbine.

    Parameters
    ----------
    rated_power : float
        Rated (aerodynamic-side) power [W] used to compute the pitch above rated.
    min_rotor_speed, max_rotor_speed : float
        Rotor-speed limits [rpm].
    design_tsr : float
        Tip-speed ratio tracked below rated [-].
    fine_pitch : float
        Blade pitch below rated [deg].
    cut_in, cut_out : float
        Wind-speed range of operation [m/s].
    generator_efficiency : float
        Electrical / aerodynamic power [-] (for electrical power outputs only).
    """

    rated_power: float
    min_rotor_speed: float
    max_rotor_speed: float
    design_tsr: float
    fine_pitch: float = 0.0
    cut_in: float = 3.0
    cut_out: float = 25.0
    generator_efficiency: float = 1.0


@dataclass(frozen=True, eq=False)
class Rotor:
    """A lifting-line rotor description.

    Parameters
    ----------
    name : str
        Short name (``"nrel5mw"``).
    r : array_like, shape (n_stations,)
        Radial position of the blade stations, measured from the rotor centre along
        the (uncurved, unconed) pitch axis [m]; strictly increasing, inside
        [hub_radius, tip_radius].
    chord : array_like, shape (n_stations,)
        Chord [m], > 0.
    twist_deg : array_like, shape (n_stations,)
        Aerodynamic twist [deg], positive toward feather (decreases α).
    airfoil_id : array_like of int, shape (n_stations,)
        Index into ``airfoils`` of each station's airfoil.
    airfoils : tuple of Airfoil
    hub_radius, tip_radius : float
        [m].
    n_blades : int
    precone_deg : float
        Precone [deg], positive tilts the blades away from the tower (upwind for an upwind
        rotor), the CCBlade/WISDEM convention.
    tilt_deg : float
        Shaft tilt [deg], positive tilts the rotor disc upward.
    hub_height : float
        [m]; needed for wind shear.
    precurve, presweep : array_like, shape (n_stations,), optional
        Out-of-plane and in-plane offsets of the blade reference axis [m], in the CCBlade
        convention: precurve positive away from the tower (upwind for an upwind rotor), so
        AeroDyn's ``BlCrvAC`` (positive downwind) enters with its sign reversed.
    precurve_tip, presweep_tip : float
        The same at the tip [m].
    schedule : OperatingSchedule, optional
        Steady control schedule (power curves, demo).
    source : str
        Where the data came from (provenance line).
    """

    name: str
    r: np.ndarray
    chord: np.ndarray
    twist_deg: np.ndarray
    airfoil_id: np.ndarray
    airfoils: tuple[Airfoil, ...]
    hub_radius: float
    tip_radius: float
    n_blades: int
    precone_deg: float = 0.0
    tilt_deg: float = 0.0
    hub_height: float = float("nan")
    precurve: np.ndarray | None = None
    presweep: np.ndarray | None = None
    precurve_tip: float = 0.0
    presweep_tip: float = 0.0
    schedule: OperatingSchedule | None = None
    source: str = field(default="<rotor>", compare=False)

    def __post_init__(self):
        """Check the description and store its arrays as float (ids as int) and its radii as float.

        Raises
        ------
        InputError
            Naming the field: :func:`_station_arrays` and :func:`_check_layout` list the checks.
        """
        stations = _station_arrays(self)
        _check_layout(self, stations["r"], stations["chord"], stations["airfoil_id"])
        stations["airfoil_id"] = stations["airfoil_id"].astype(int)
        for name, value in stations.items():
            object.__setattr__(self, name, value)
        object.__setattr__(self, "airfoils", tuple(self.airfoils))
        object.__setattr__(self, "hub_radius", float(self.hub_radius))
        object.__setattr__(self, "tip_radius", float(self.tip_radius))
        object.__setattr__(self, "n_blades", int(self.n_blades))

    def __repr__(self) -> str:
        """A short summary (the arrays are too long to print; ``r``, ``chord`` ... hold them)."""
        return (f"Rotor({self.name!r}, R = {self.tip_radius:.4g} m, hub {self.hub_radius:.4g} m, {self.n_blades} blades, "
                f"{self.n_stations} stations, {len(self.airfoils)} airfoils, precone {self.precone_deg:g}°, "
                f"tilt {self.tilt_deg:g}°, {'with' if self.schedule is not None else 'no'} operating schedule)")

    @property
    def n_stations(self) -> int:
        return int(self.r.size)

    @property
    def eta(self) -> np.ndarray:
        """Spanwise coordinate η = r / R_tip [-] of the stations."""
        return self.r / self.tip_radius

    @property
    def rotor_radius(self) -> float:
        """Radius of the swept disc [m]: tip radius times cos(precone), plus precurve."""
        pc = np.radians(self.precone_deg)
        return float(self.tip_radius * np.cos(pc) + self.precurve_tip * np.sin(pc))

    @property
    def swept_area(self) -> float:
        """Swept area π R² [m^2] with R = :attr:`rotor_radius`."""
        return float(np.pi * self.rotor_radius ** 2)


def _station_arrays(rotor: Rotor) -> dict[str, np.ndarray]:
    """The per-station inputs of ``rotor`` as 1-D arrays, one value per station, all finite.

    Parameters
    ----------
    rotor : Rotor
        As given (before :meth:`Rotor.__post_init__` stores the arrays).

    Returns
    -------
    dict of ndarray, shape (n_stations,)
        ``r``, ``chord``, ``twist_deg``, ``precurve``, ``presweep`` as float (precurve and
        presweep zero when not given) and ``airfoil_id`` as given (of an integer type).

    Raises
    ------
    InputError
        Naming the field: not numbers, not 1-D, a length other than that of ``r``, fewer than
        2 stations, a value that is not finite, airfoil ids that are not integers.
    """
    src = rotor.source

    def arr(name, value):
        try:
            a = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"expected numbers, got {value!r}", src, field=name) from None
        if a.ndim != 1:
            raise InputError(f"expected a 1-D array, got shape {a.shape}", src, field=name)
        return a
    r = arr("r", rotor.r)
    n = r.size
    chord = arr("chord", rotor.chord)
    twist = arr("twist_deg", rotor.twist_deg)
    precurve = np.zeros(n) if rotor.precurve is None else arr("precurve", rotor.precurve)
    presweep = np.zeros(n) if rotor.presweep is None else arr("presweep", rotor.presweep)
    ids = np.asarray(rotor.airfoil_id)
    for name, a in (("chord", chord), ("twist_deg", twist), ("precurve", precurve),
                    ("presweep", presweep), ("airfoil_id", ids)):
        if a.shape != (n,):
            raise InputError(f"has {a.size} values but there are {n} stations", src, field=name)
    if n < 2:
        raise InputError("a blade needs at least 2 stations", src, field="r")
    for name, a in (("r", r), ("chord", chord), ("twist_deg", twist),
                    ("precurve", precurve), ("presweep", presweep)):
        bad = np.flatnonzero(~np.isfinite(a))
        if bad.size:
            raise InputError(f"station {bad[0]} is not finite ({a[bad[0]]!r})", src, field=name)
    if not np.issubdtype(ids.dtype, np.integer):
        raise InputError("airfoil ids must be integers", src, field="airfoil_id")
    return {"r": r, "chord": chord, "twist_deg": twist, "precurve": precurve, "presweep": presweep,
            "airfoil_id": ids}


def _check_layout(rotor: Rotor, r: np.ndarray, chord: np.ndarray, ids: np.ndarray) -> None:
    """Refuse a blade layout that cannot be a rotor.

    Parameters
    ----------
    rotor : Rotor
        As given (its blade count, hub and tip radius [m], airfoils, precone and tilt [deg]).
    r, chord : ndarray, shape (n_stations,)
        Station radii and chords [m] (:func:`_station_arrays`).
    ids : ndarray of int, shape (n_stations,)
        Airfoil index of each station.

    Raises
    ------
    InputError
        Naming the field: fewer than 1 blade; not 0 < hub radius < tip radius; a chord <= 0;
        radii not strictly increasing or outside [hub_radius, tip_radius] (to 1e-6 of the tip
        radius); an airfoil id outside the airfoils; a precone or tilt that is not finite.
    """
    src = rotor.source
    if int(rotor.n_blades) < 1:
        raise InputError(f"n_blades must be >= 1, got {rotor.n_blades}", src, field="n_blades")
    hub, tip = float(rotor.hub_radius), float(rotor.tip_radius)
    if not (0.0 < hub < tip):
        raise InputError(f"need 0 < hub_radius < tip_radius, got {hub:g} and {tip:g} m", src,
                         field="hub_radius")
    bad = np.flatnonzero(chord <= 0)
    if bad.size:
        raise InputError(f"chord must be > 0, station {bad[0]} has {chord[bad[0]]:g} m", src, field="chord")
    bad = np.flatnonzero(np.diff(r) <= 0)
    if bad.size:
        raise InputError(f"radii must be strictly increasing (station {bad[0] + 1})", src, field="r")
    tol = 1e-6 * tip
    bad = np.flatnonzero((r < hub - tol) | (r > tip + tol))
    if bad.size:
        raise InputError(f"station {bad[0]} at r = {r[bad[0]]:g} m lies outside "
                         f"[hub_radius, tip_radius] = [{hub:g}, {tip:g}] m", src, field="r")
    if ids.min() < 0 or ids.max() >= len(rotor.airfoils):
        raise InputError(f"airfoil ids must lie in 0..{len(rotor.airfoils) - 1}", src, field="airfoil_id")
    for name, value in (("precone_deg", rotor.precone_deg), ("tilt_deg", rotor.tilt_deg)):
        if not np.isfinite(value):
            raise InputError("must be finite", src, field=name)
