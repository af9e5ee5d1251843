"""Rotors from OpenFAST decks: the ``.fst`` glue-code file, ElastoDyn, AeroDyn 15, InflowWind.

:func:`read_openfast` follows ``EDFile``, ``AeroFile`` and ``InflowFile`` of a ``.fst``
(paths relative to the referencing file, as OpenFAST resolves them) and returns an
:class:`OpenFastDeck`; :meth:`OpenFastDeck.rotor` builds the :class:`~calib.rotor.geometry.Rotor`.
Only the files the rotor needs are opened: ServoDyn, BeamDyn, tower, controller and wind
files may be absent.

Values are looked up by keyword (:class:`~calib.rotor.input_file.InputFileValues`), not by line
position, so decks of several OpenFAST generations read alike (``.fst`` with or without the
``ENVIRONMENTAL CONDITIONS`` section, ElastoDyn with or without ``Gravity``, AeroDyn 15 with
``WakeMod``/``AFAeroMod`` or ``Wake_Mod``/``UA_Mod``). NREL's ``openfast-io`` was not used: it
reads positionally, for the newest OpenFAST input layout only (5.0.0 fails on the r-test
NREL 5-MW files of OpenFAST 3.5 and 4, the ``.fst``, ElastoDyn and both AeroDyn files alike),
and it pulls in pandas, deepdiff and ruamel.yaml.

Sign conventions (ElastoDyn -> :class:`Rotor`, i.e. CCBlade/WISDEM)
-------------------------------------------------------------------
ElastoDyn measures ``PreCone`` and ``ShftTilt`` in its own axes (x downwind, z up): a negative
``PreCone`` cones the blades upwind, a negative ``ShftTilt`` raises the upwind (hub) end of
the shaft, and ``OverHang < 0`` puts the rotor upwind of the tower. The Rotor uses CCBlade's
signs: precone positive away from the tower, tilt positive with the rotor disc facing up.
For an upwind rotor (the only kind the Rotor describes)::

    precone_deg = -PreCone(1)        (NREL 5-MW: -(-2.5) = 2.5 deg)
    tilt_deg    = -ShftTilt          (NREL 5-MW: -(-5)   = 5 deg)

A downwind rotor (``OverHang > 0``) is refused rather than converted silently.

Hub height (rotor apex above the ground, onshore; above MSL offshore), from the ElastoDyn
geometry: the shaft meets the yaw axis ``Twr2Shft`` above the tower top and the apex lies
``OverHang`` along the tilted shaft::

    hub_height = TowerHt + Twr2Shft + OverHang * sin(ShftTilt)
               = TowerHt + Twr2Shft + |OverHang| * sin(tilt_deg)     (upwind rotor)

NREL 5-MW: 87.6 + 1.96256 + (-5.0191) sin(-5 deg) = 90.000003 m (the report's 90 m).

Tip radius: the aerodynamic blade is AeroDyn's, r = ``HubRad`` + ``BlSpn``, and the tip radius
is the last AeroDyn node, as for the embedded rotors (:func:`~calib.rotor.aerodyn.rotor_from_aerodyn`).
ElastoDyn's ``TipRad`` (the structural tip) is checked against it: a node beyond ``TipRad`` is
an error; the r-test NREL 5-MW has ``TipRad`` = 63 m and its last node at 62.9999 m (the blade
file's comment: 61.5 m was shortened to 61.4999 m for BeamDyn coupling).

Fluid: AeroDyn's ``AirDens``/``KinVisc`` when numbers; when ``"default"`` (OpenFAST >= 3.5),
the ``.fst`` values; None when neither says.

Reference: OpenFAST documentation (https://openfast.readthedocs.io): ElastoDyn, AeroDyn and
InflowWind input files; glue-code input file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.rotor.aerodyn import read_aerodyn_blade, rotor_from_aerodyn
from calib.rotor.aerodyn_main import AeroDynMain, read_aerodyn_main
from calib.rotor.input_file import InputFileValues
from calib.rotor.geometry import Rotor

# InflowWind WindType values (InflowWind input file)
WIND_TYPES = {1: "steady", 2: "uniform", 3: "binary TurbSim full field", 4: "binary Bladed-style full field",
              5: "HAWC full field", 6: "user defined", 7: "native Bladed full field", 8: "4D"}


# ---------------------------------------------------------------- ElastoDyn
@dataclass(frozen=True)
class ElastoDynRotor:
    """Rotor and nacelle geometry of an ElastoDyn input file, in OpenFAST's signs.

    Attributes
    ----------
    n_blades : int
        ``NumBl``.
    tip_radius : float
        ``TipRad``, rotor apex to blade tip [m].
    hub_radius : float
        ``HubRad``, rotor apex to blade root [m].
    precone_openfast : float
        ``PreCone(1)`` [deg], negative = blades coned upwind.
    shaft_tilt_openfast : float
        ``ShftTilt`` [deg], negative = upwind end of the shaft raised.
    overhang : float
        ``OverHang``, yaw axis to rotor apex along the shaft [m], negative upwind.
    tower_to_shaft : float
        ``Twr2Shft``, tower top to shaft, vertical [m].
    tower_height : float
        ``TowerHt``, tower top above ground (onshore), MSL (offshore) or seabed (MHK) [m].
    source : str
        The ElastoDyn file.
    lines : dict
        Keyword -> 1-based line of each value.
    """

    n_blades: int
    tip_radius: float
    hub_radius: float
    precone_openfast: float
    shaft_tilt_openfast: float
    overhang: float
    tower_to_shaft: float
    tower_height: float
    source: str
    lines: dict = field(default_factory=dict, compare=False)

    @property
    def precone_deg(self) -> float:
        """Precone [deg], CCBlade sign (positive away from the tower): -PreCone(1)."""
        return -self.precone_openfast

    @property
    def tilt_deg(self) -> float:
        """Shaft tilt [deg], CCBlade sign (positive: rotor disc faces up): -ShftTilt."""
        return -self.shaft_tilt_openfast

    @property
    def hub_height(self) -> float:
        """Rotor apex height [m]: TowerHt + Twr2Shft + OverHang sin(ShftTilt)."""
        return float(self.tower_height + self.tower_to_shaft
                     + self.overhang * np.sin(np.radians(self.shaft_tilt_openfast)))


def read_elastodyn(path) -> ElastoDynRotor:
    """Read ``NumBl``, ``TipRad``, ``HubRad``, ``PreCone(1)``, ``ShftTilt``, ``OverHang``,
    ``Twr2Shft`` and ``TowerHt`` of an ElastoDyn (or SimplifiedElastoDyn) input file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    ElastoDynRotor
        Values in OpenFAST's signs; the converted ones are its properties.

    Raises
    ------
    InputError
        A keyword missing or not a number (file, line and keyword named), ``NumBl`` < 1,
        ``HubRad`` <= 0 or ``TipRad`` <= ``HubRad``, a downwind rotor (``OverHang`` > 0).
    """
    v = InputFileValues(path)
    src = v.source
    precone_key = "PreCone(1)" if "PreCone(1)" in v else ("PreCone" if "PreCone" in v else "PreCone(1)")
    values = {"NumBl": v.integer("NumBl", "integer blade count")}
    for key, what in (("TipRad", "tip radius [m]"), ("HubRad", "hub radius [m]"),
                      (precone_key, "precone angle [deg]"), ("ShftTilt", "shaft tilt [deg]"),
                      ("OverHang", "overhang [m]"), ("Twr2Shft", "tower-top to shaft distance [m]"),
                      ("TowerHt", "tower height [m]")):
        values[key] = v.number(key, f"a {what}")
    lines = {key: v.get(key).line for key in values}
    if not 1 <= values["NumBl"] <= 3:
        raise InputError(f"expected 1 to 3 blades, got {values['NumBl']}", src, lines["NumBl"], "NumBl")
    if values["HubRad"] <= 0:
        raise InputError(f"must be > 0, got {values['HubRad']:g} m", src, lines["HubRad"], "HubRad")
    if values["TipRad"] <= values["HubRad"]:
        raise InputError(f"must exceed HubRad = {values['HubRad']:g} m, got {values['TipRad']:g} m", src,
                         lines["TipRad"], "TipRad")
    if values["OverHang"] > 0:
        raise InputError(f"OverHang = {values['OverHang']:g} m > 0 is a downwind rotor; calib's Rotor "
                         "describes upwind rotors (signs of precone and tilt)", src, lines["OverHang"],
                         "OverHang")
    rotor = ElastoDynRotor(n_blades=values["NumBl"], tip_radius=values["TipRad"], hub_radius=values["HubRad"],
                           precone_openfast=values[precone_key], shaft_tilt_openfast=values["ShftTilt"],
                           overhang=values["OverHang"], tower_to_shaft=values["Twr2Shft"],
                           tower_height=values["TowerHt"], source=src, lines=lines)
    if not np.isfinite(rotor.hub_height):
        raise InputError(f"the hub height TowerHt + Twr2Shft + OverHang sin(ShftTilt) is not a finite number "
                         f"(TowerHt = {values['TowerHt']:g} m)", src, lines["TowerHt"], "TowerHt")
    return rotor


# ---------------------------------------------------------------- InflowWind
@dataclass(frozen=True)
class InflowWindSetup:
    """What an InflowWind input file says about the mean wind profile.

    Attributes
    ----------
    wind_type : int
        ``WindType`` (:data:`WIND_TYPES`).
    shear_exponent : float or None
        ``PLExp`` (also spelled ``PLexp``) [-], power-law exponent of the steady-wind section;
        None when absent.
    reference_height : float or None
        ``RefHt`` [m] of the steady-wind section; None when absent.
    source : str
    notes : tuple of str
        E.g. that OpenFAST uses ``PLExp`` only for ``WindType = 1``.
    """

    wind_type: int
    shear_exponent: float | None
    reference_height: float | None
    source: str
    notes: tuple[str, ...] = ()


def read_inflowwind(path) -> InflowWindSetup:
    """Read ``WindType``, ``PLExp`` and ``RefHt`` of an InflowWind input file.

    For ``WindType`` other than 1 (steady) InflowWind does not apply ``PLExp``: a full-field
    wind file carries its own profile (the r-test 12 m/s TurbSim input, 5MW_Baseline/Wind/
    90m_12mps_twr.inp, asks for a power law, IEC normal turbulence, ``PLExp = "default"``, which
    TurbSim sets to 0.2 for that model). The values are returned as the file states them,
    with a note.

    Raises
    ------
    InputError
        ``WindType`` missing or not an integer, ``PLExp``/``RefHt`` present but not numbers,
        ``RefHt`` <= 0.
    """
    v = InputFileValues(path)
    src = v.source
    wind_type = v.integer("WindType")
    shear = v.number("PLExp", "a power-law exponent [-]") if "PLExp" in v else None
    ref = v.number("RefHt", "a reference height [m]") if "RefHt" in v else None
    if ref is not None and ref <= 0:
        raise InputError(f"must be > 0, got {ref:g} m", src, v.get("RefHt").line, "RefHt")
    notes = []
    if wind_type != 1 and (shear is not None or ref is not None):
        notes.append(f"{src}: WindType = {wind_type} ({WIND_TYPES.get(wind_type, 'unknown')}); InflowWind "
                     "applies PLExp/RefHt only to steady wind (WindType = 1), the values are the file's "
                     "steady-wind section")
    return InflowWindSetup(wind_type=wind_type, shear_exponent=shear, reference_height=ref, source=src,
                           notes=tuple(notes))


# ---------------------------------------------------------------- the deck
@dataclass(frozen=True)
class OpenFastDeck:
    """The parts of an OpenFAST deck that define a BEM rotor and its set-up.

    Attributes
    ----------
    fst : Path
        The ``.fst`` file.
    elastodyn : ElastoDynRotor
    aerodyn : AeroDynMain
    inflow : InflowWindSetup or None
        None when ``CompInflow = 0`` (still air) or the deck takes wind from elsewhere.
    air_density : float or None
        [kg/m^3]: AeroDyn's ``AirDens``, or the ``.fst`` value when AeroDyn says ``"default"``.
    kinematic_viscosity : float or None
        [m^2/s], the same rule with ``KinVisc``.
    files : tuple of Path
        Every file read: .fst, ElastoDyn, AeroDyn main, blade, airfoils, InflowWind.
    notes : tuple of str
        Facts a user should know (defaults resolved, values OpenFAST ignores, TipRad vs blade).
    """

    fst: Path
    elastodyn: ElastoDynRotor
    aerodyn: AeroDynMain
    inflow: InflowWindSetup | None
    air_density: float | None
    kinematic_viscosity: float | None
    files: tuple[Path, ...]
    notes: tuple[str, ...] = ()

    def rotor(self, name: str | None = None) -> Rotor:
        """The :class:`Rotor` of this deck (conventions in the module notes).

        Parameters
        ----------
        name : str, optional
            Default the ``.fst`` file stem.
        """
        ed = self.elastodyn
        blade = read_aerodyn_blade(self.aerodyn.blade_file)
        r_tip = ed.hub_radius + float(blade["span"][-1])
        if r_tip > ed.tip_radius * (1 + 1e-9):
            raise InputError(f"the last blade node lies at HubRad + BlSpn = {r_tip:g} m, beyond ElastoDyn's "
                             f"TipRad = {ed.tip_radius:g} m ({self.aerodyn.blade_file})", ed.source,
                             ed.lines.get("TipRad"), "TipRad")
        return rotor_from_aerodyn(self.aerodyn.blade_file, self.aerodyn.airfoil_files, hub_radius=ed.hub_radius,
                                  n_blades=ed.n_blades, precone_deg=ed.precone_deg, tilt_deg=ed.tilt_deg,
                                  hub_height=ed.hub_height, name=name or self.fst.stem,
                                  source=f"OpenFAST deck {self.fst}")


def _fst_fluid(v: InputFileValues, key: str) -> float | None:
    if key not in v:
        return None
    out = v.number(key, "a positive number")
    if out <= 0:
        raise InputError(f"must be > 0, got {out:g}", v.source, v.get(key).line, key)
    return out


def read_openfast(path) -> OpenFastDeck:
    """Read the rotor-defining parts of an OpenFAST deck from its ``.fst`` file.

    Parameters
    ----------
    path : str or Path
        The ``.fst`` file. ``EDFile``, ``AeroFile`` and (when ``CompInflow = 1``)
        ``InflowFile`` are followed, relative to the ``.fst``; the AeroDyn blade and airfoil
        files relative to the AeroDyn main file.

    Returns
    -------
    OpenFastDeck

    Raises
    ------
    InputError
        ``CompAero`` not 2 (AeroDyn 15), a referenced file missing (the error names the
        referencing file, its line and keyword), or any error of the module readers.
    """
    v = InputFileValues(path)
    src = v.source
    comp_aero = v.integer("CompAero")
    if comp_aero != 2:
        raise InputError(f"expected 2 (AeroDyn 15), got {comp_aero}: calib reads AeroDyn 15 decks only", src,
                         v.get("CompAero").line, "CompAero")
    comp_inflow = v.integer("CompInflow")
    ed_file = v.file("EDFile")
    ad_file = v.file("AeroFile")
    elastodyn = read_elastodyn(ed_file)
    aerodyn = read_aerodyn_main(ad_file)
    notes = []
    inflow, files = None, [Path(path), ed_file, ad_file]
    if comp_inflow == 1:
        if_file = v.file("InflowFile")
        inflow = read_inflowwind(if_file)
        files.append(if_file)
        notes.extend(inflow.notes)
    else:
        notes.append(f"{src}: CompInflow = {comp_inflow}, no InflowWind file read (no shear or reference height)")
    fluid = {}
    for key, value, name in (("AirDens", aerodyn.air_density, "air_density"),
                             ("KinVisc", aerodyn.kinematic_viscosity, "kinematic_viscosity")):
        if value is not None:
            fluid[name] = value
            continue
        fluid[name] = _fst_fluid(v, key)
        where = f"{aerodyn.source} line {aerodyn.lines[key]}"
        if fluid[name] is None:
            notes.append(f"{where}: {key} = \"default\" and the .fst has no {key} (older OpenFAST): not known")
        else:
            notes.append(f"{where}: {key} = \"default\" -> {fluid[name]:g} from {src} line {v.get(key).line}")
    files += [aerodyn.blade_file, *aerodyn.airfoil_files]
    blade_tip = elastodyn.hub_radius + float(read_aerodyn_blade(aerodyn.blade_file)["span"][-1])
    if abs(blade_tip - elastodyn.tip_radius) > 1e-9 * elastodyn.tip_radius:
        notes.append(f"{elastodyn.source}: TipRad = {elastodyn.tip_radius:g} m, the AeroDyn blade ends at "
                     f"HubRad + BlSpn = {blade_tip:.6g} m; the rotor's tip radius is the AeroDyn one")
    return OpenFastDeck(fst=Path(path), elastodyn=elastodyn, aerodyn=aerodyn, inflow=inflow,
                        air_density=fluid["air_density"], kinematic_viscosity=fluid["kinematic_viscosity"],
                        files=tuple(dict.fromkeys(files)), notes=tuple(notes))


def rotor_from_openfast(path, name: str | None = None) -> Rotor:
    """The :class:`Rotor` of an OpenFAST deck (``read_openfast(path).rotor(name)``)."""
    return read_openfast(path).rotor(name)
