"""The ``[rotor]`` table of a workflow: which files define the rotor, and what they say.

:func:`rotor_from_table` turns the table into a :class:`RotorSource`: the
:class:`~calib.rotor.geometry.Rotor` plus what the files state about the BEM set-up and
the fluid (None where they say nothing), and the list of files read.

Sources (exactly one)::

    name = "nrel5mw"                       # embedded rotor (calib.rotor.library.ROTORS)
    openfast = "deck/Turbine.fst"          # OpenFAST deck: ElastoDyn, AeroDyn 15, InflowWind
    aerodyn = "deck/Turbine_AeroDyn15.dat" # AeroDyn 15 main file (blade file and AFNames)
    aerodyn_blade = "blade.dat"            # AeroDyn 15 blade file ...
    airfoils = ["cyl.dat", "du40.dat"]     # ... and its airfoil files in BlAFID order
    windio = "turbine.yaml"                # windIO turbine file

Hub and orientation keys: ``hub_radius`` [m], ``precone`` [deg], ``tilt`` [deg],
``hub_height`` [m], ``n_blades``. They are required exactly when the files do not carry
them (``aerodyn`` and ``aerodyn_blade`` + ``airfoils``: all five) and refused when the files
do (``name``, ``openfast``, ``windio``): one value per quantity, never a silent default and
never two competing ones. To run a rotor at another precone or tilt than its files state,
override it in the model set-up (``[model] precone``, ``[model] tilt``), where the change is
visible as a model choice. Angles use the Rotor's (CCBlade) signs: precone positive away
from the tower, tilt positive with the rotor disc facing up.

Relative paths are relative to ``base_dir`` (the folder of the workflow file). Every error
is an :class:`~calib.errors.InputError` naming the workflow file and the key
(``rotor.hub_radius``), or the rotor file, its line and its keyword.

Provenance (:mod:`calib.rotor.provenance`):
every file a table's rotor was read from is remembered with its SHA-256 (taken when read) and
its path relative to the workflow's folder (:func:`~calib.rotor.provenance.recorded_rotor_files`, which a model's
``spec()`` records in a result). A result written without its rotor data rebuilds the rotor
from those files (:func:`rotor_from_recorded_files`), refusing any that is missing or changed
since the run.
"""

from __future__ import annotations

import reprlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.errors import InputError, unknown_key
from calib.rotor.aerodyn import rotor_from_aerodyn
from calib.rotor.aerodyn_main import read_aerodyn_main
from calib.rotor.geometry import Rotor
from calib.rotor.library import ROTORS, load_rotor
from calib.rotor.openfast import read_openfast
from calib.rotor.provenance import check_files_read, check_followed_files, located_table, records_by_path
from calib.rotor.windio import load_windio, read_windio

SOURCE_KEYS = ("name", "openfast", "aerodyn", "aerodyn_blade", "windio")
SETUP_KEYS = ("hub_radius", "precone", "tilt", "hub_height", "n_blades")
VALID_KEYS = SOURCE_KEYS + ("airfoils",) + SETUP_KEYS
# which hub and orientation keys each source carries itself
_CARRIED = {"name": SETUP_KEYS, "openfast": SETUP_KEYS, "windio": SETUP_KEYS, "aerodyn": (),
            "aerodyn_blade": ()}
_LABEL = {"name": "embedded rotor", "openfast": "OpenFAST deck", "windio": "windIO file",
          "aerodyn": "AeroDyn main file", "aerodyn_blade": "AeroDyn blade file"}
_WHAT = {"hub_radius": "hub radius [m], > 0", "precone": "precone angle [deg], positive away from the tower",
         "tilt": "shaft tilt [deg], positive with the rotor disc facing up", "hub_height": "hub height [m], > 0",
         "n_blades": "number of blades, an integer >= 1"}


@dataclass(frozen=True)
class RotorSource:
    """A rotor and what its files say about the model set-up and the fluid.

    Attributes
    ----------
    rotor : Rotor
    tip_loss, hub_loss : bool or None
        Prandtl tip / hub loss (AeroDyn ``TipLoss``, ``HubLoss``).
    tangential_induction : bool or None
        Tangential induction a' (AeroDyn ``TanInd``).
    drag_in_axial_induction, drag_in_tangential_induction : bool or None
        Drag in the induction equations (AeroDyn ``AIDrag``, ``TIDrag``).
    air_density : float or None
        Fluid density [kg/m^3] (AeroDyn ``AirDens``, the ``.fst`` for ``"default"``, windIO
        ``environment.air_density``).
    kinematic_viscosity : float or None
        [m^2/s] (AeroDyn ``KinVisc``; windIO ``air_dyn_viscosity / air_density``).
    shear_exponent : float or None
        Power-law exponent [-] (InflowWind ``PLExp``, windIO ``environment.shear_exp``).
    reference_height : float or None
        Height of the reference wind speed [m] (InflowWind ``RefHt``).
    files : tuple of Path
        Every file read, for provenance and input hashes (empty for an embedded rotor,
        whose package data is named in ``rotor.source``).
    notes : tuple of str
        What a user should know about how the files were read (defaults resolved, values
        OpenFAST does not use, tip radius of ElastoDyn vs AeroDyn).

    Every set-up field is None where the files do not say.
    """

    rotor: Rotor
    tip_loss: bool | None = None
    hub_loss: bool | None = None
    tangential_induction: bool | None = None
    drag_in_axial_induction: bool | None = None
    drag_in_tangential_induction: bool | None = None
    air_density: float | None = None
    kinematic_viscosity: float | None = None
    shear_exponent: float | None = None
    reference_height: float | None = None
    files: tuple[Path, ...] = ()
    notes: tuple[str, ...] = ()


def _key(name: str) -> str:
    return f"rotor.{name}"


def _path(table: dict, key: str, source: str, base_dir: Path) -> Path:
    value = table[key]
    if not isinstance(value, str) or not value.strip():
        raise InputError(f"expected a file name (string), got {value!r}", source, None, _key(key))
    path = _resolve(value, base_dir, source, _key(key))
    if not path.is_file():
        raise InputError(f"file not found: {value!r} (looked for {path})", source, None, _key(key))
    return path


def _resolve(value: str, base_dir: Path | None, source: str, key: str) -> Path:
    path = Path(value).expanduser()
    if not path.is_absolute():
        if base_dir is None:
            raise InputError(f"relative path {value!r}, but no folder to resolve it against (expected an absolute "
                             "path)", source, None, key)
        path = base_dir / path
    return path


def _setup_value(table: dict, key: str, source: str):
    value = table[key]
    if key == "n_blades":
        if (isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value)
                or value != int(value) or value < 1):
            raise InputError(f"expected {_WHAT[key]}, got {value!r}", source, None, _key(key))
        return int(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(f"expected {_WHAT[key]}, got {value!r}", source, None, _key(key))
    if key in ("hub_radius", "hub_height") and value <= 0:
        raise InputError(f"expected {_WHAT[key]}, got {value!r}", source, None, _key(key))
    return float(value)


def _check_keys(table: dict, source: str) -> str:
    """Validate the key set; return the source kind."""
    if not isinstance(table, dict):
        raise InputError(f"expected a table, got {type(table).__name__}", source, None, "rotor")
    for key in table:
        if key not in VALID_KEYS:
            raise InputError(unknown_key(key, VALID_KEYS, label="valid keys"), source, None, _key(key))
    given = [k for k in SOURCE_KEYS if k in table]
    if "airfoils" in table and "aerodyn_blade" not in table:
        raise InputError("'airfoils' needs 'aerodyn_blade' (the AeroDyn blade file they belong to)", source, None,
                         _key("aerodyn_blade"))
    if "aerodyn_blade" in table and "airfoils" not in table:
        raise InputError("'aerodyn_blade' needs 'airfoils', the list of airfoil files in BlAFID order", source,
                         None, _key("airfoils"))
    if not given:
        raise InputError(f"no rotor given; set exactly one of: {', '.join(SOURCE_KEYS)} "
                         "(aerodyn_blade together with airfoils)", source, None, "rotor")
    if len(given) > 1:
        raise InputError(f"{' and '.join(given)} both define the rotor; keep exactly one of: "
                         f"{', '.join(SOURCE_KEYS)}", source, None, _key(given[1]))
    kind = given[0]
    carried = _CARRIED[kind]
    for key in SETUP_KEYS:
        if key in table and key in carried:
            hint = (" To run at another angle, set it in the model set-up ([model] "
                    f"{key})." if key in ("precone", "tilt") else "")
            raise InputError(f"the {_LABEL[kind]} ({kind}) already defines {key}; remove it from [rotor] "
                             f"(one value per quantity).{hint}", source, None, _key(key))
        if key not in table and key not in carried:
            raise InputError(f"required with {kind}: the {_LABEL[kind]} does not give the {_WHAT[key]}",
                             source, None, _key(key))
    return kind


def rotor_from_table(table: dict, source: str, base_dir) -> RotorSource:
    """Build the rotor of a workflow's ``[rotor]`` table.

    Parameters
    ----------
    table : dict
        The ``[rotor]`` table (module notes list the keys).
    source : str
        The workflow file, named in errors.
    base_dir : str or Path or None
        Folder relative paths are resolved against (the workflow file's folder); None: the
        table's paths must be absolute.

    Returns
    -------
    RotorSource

    Raises
    ------
    InputError
        Unknown key, no or several sources, a hub/orientation key missing where the files
        lack it or given where they carry it, a value of the wrong type, a file not found
        (``source`` and ``rotor.<key>`` named), a relative path without ``base_dir``, or an
        error inside a rotor file (that file, line and keyword named).

    Notes
    -----
    ``RotorSource.files`` lists every file read; :func:`file_provenance` turns them into
    the provenance a result records.
    """
    src = str(source)
    base = None if base_dir is None else Path(base_dir)
    return _read(table, src, base)


def _read(table: dict, src: str, base: Path | None) -> RotorSource:
    kind = _check_keys(table, src)
    setup = {k: _setup_value(table, k, src) for k in SETUP_KEYS if k in table}

    if kind == "name":
        return _from_name(table, src)

    if kind == "openfast":
        return _from_openfast(table, src, base)

    geometry = dict(hub_radius=setup.get("hub_radius"), n_blades=setup.get("n_blades"),
                    precone_deg=setup.get("precone"),
                    tilt_deg=setup.get("tilt"), hub_height=setup.get("hub_height"))

    if kind == "aerodyn":
        return _from_aerodyn(table, src, base, geometry)

    if kind == "aerodyn_blade":
        return _from_aerodyn_blade(table, src, base, geometry)

    return _from_windio(table, src, base)


def _from_name(table: dict, src: str) -> RotorSource:
    """An embedded rotor (:data:`calib.rotor.library.ROTORS`), by its ``name``."""
    name = table["name"]
    if not isinstance(name, str) or name.strip().lower() not in ROTORS:
        raise InputError(f"unknown rotor {name!r}; valid names: {', '.join(ROTORS)}", src, None, _key("name"))
    return RotorSource(rotor=load_rotor(name))


def _from_openfast(table: dict, src: str, base: Path | None) -> RotorSource:
    """The rotor, BEM set-up, fluid and shear of the OpenFAST deck named by ``openfast``."""
    deck = read_openfast(_path(table, "openfast", src, base))
    ad, inflow = deck.aerodyn, deck.inflow
    return RotorSource(rotor=deck.rotor(), tip_loss=ad.tip_loss, hub_loss=ad.hub_loss,
                       tangential_induction=ad.tangential_induction,
                       drag_in_axial_induction=ad.drag_in_axial_induction,
                       drag_in_tangential_induction=ad.drag_in_tangential_induction,
                       air_density=deck.air_density, kinematic_viscosity=deck.kinematic_viscosity,
                       shear_exponent=None if inflow is None else inflow.shear_exponent,
                       reference_height=None if inflow is None else inflow.reference_height,
                       files=deck.files, notes=deck.notes)


def _from_aerodyn(table: dict, src: str, base: Path | None, geometry: dict) -> RotorSource:
    """The rotor, BEM set-up and fluid of the AeroDyn 15 main file named by ``aerodyn``.

    ``geometry``: hub radius [m], n_blades, precone [deg], tilt [deg] and hub height [m] of
    the ``[rotor]`` table, as keywords of :func:`~calib.rotor.aerodyn.rotor_from_aerodyn`.
    """
    path = _path(table, "aerodyn", src, base)
    ad = read_aerodyn_main(path)
    notes = tuple(f"{ad.source} line {ad.lines[key]}: {key} = \"default\" (given by the OpenFAST .fst, "
                  "not read here): not known" for key, value in
                  (("AirDens", ad.air_density), ("KinVisc", ad.kinematic_viscosity)) if value is None)
    rotor = rotor_from_aerodyn(ad.blade_file, ad.airfoil_files, name=path.stem,
                               source=f"AeroDyn 15 {path} + [rotor] of {src}", **geometry)
    return RotorSource(rotor=rotor, tip_loss=ad.tip_loss, hub_loss=ad.hub_loss,
                       tangential_induction=ad.tangential_induction,
                       drag_in_axial_induction=ad.drag_in_axial_induction,
                       drag_in_tangential_induction=ad.drag_in_tangential_induction,
                       air_density=ad.air_density, kinematic_viscosity=ad.kinematic_viscosity,
                       files=(path, ad.blade_file, *ad.airfoil_files), notes=notes)


def _from_aerodyn_blade(table: dict, src: str, base: Path | None, geometry: dict) -> RotorSource:
    """The rotor of the AeroDyn 15 blade file ``aerodyn_blade`` and its ``airfoils`` (BlAFID order).

    ``geometry`` as for :func:`_from_aerodyn`.
    """
    blade = _path(table, "aerodyn_blade", src, base)
    names = table["airfoils"]
    if isinstance(names, str) or not isinstance(names, (list, tuple)) or not names:
        raise InputError(f"expected a non-empty list of airfoil files in BlAFID order, got {names!r}", src,
                         None, _key("airfoils"))
    airfoils = []
    for k, name in enumerate(names):
        if not isinstance(name, str) or not name.strip():
            raise InputError(f"entry {k + 1}: expected a file name, got {name!r}", src, None, _key("airfoils"))
        path = _resolve(name, base, src, _key("airfoils"))
        if not path.is_file():
            raise InputError(f"entry {k + 1}: file not found: {name!r} (looked for {path})", src, None,
                             _key("airfoils"))
        airfoils.append(path)
    rotor = rotor_from_aerodyn(blade, airfoils, name=blade.stem,
                               source=f"AeroDyn 15 blade {blade} + [rotor] of {src}", **geometry)
    return RotorSource(rotor=rotor, files=(blade, *airfoils))


def _from_windio(table: dict, src: str, base: Path | None) -> RotorSource:
    """The rotor and the ``environment`` (air density [kg/m^3], viscosity, shear) of the windIO file ``windio``."""
    path = _path(table, "windio", src, base)
    rotor = read_windio(path)
    env = load_windio(path).get("environment") or {}
    if not isinstance(env, dict):
        raise InputError(f"expected a mapping, got {type(env).__name__}", str(path), None, "environment")
    rho = env.get("air_density")
    mu = env.get("air_dyn_viscosity")
    shear = env.get("shear_exp")

    def number(value, key):
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
            raise InputError(f"expected a non-negative number, got {reprlib.repr(value)}", str(path), None,
                             f"environment.{key}")
        return float(value)

    rho, mu, shear = number(rho, "air_density"), number(mu, "air_dyn_viscosity"), number(shear, "shear_exp")
    nu = mu / rho if (mu is not None and rho) else None
    return RotorSource(rotor=rotor, air_density=rho, kinematic_viscosity=nu, shear_exponent=shear, files=(path,))


# ----------------------------------------------------------------------------- recorded rotors
def rotor_from_recorded_files(table: dict, provenance: dict | None, result_dir, source: str) -> RotorSource:
    """Rebuild a recorded rotor from its files, refusing any that is missing or changed.

    For results that recorded no rotor data (written by older versions). Each file the
    table names is looked for at its recorded absolute path, then (if not there) in
    ``result_dir`` under its recorded path relative to the workflow's folder, then in
    ``result_dir`` under its name. Where ``provenance`` (:func:`recorded_rotor_files`)
    holds a file's SHA-256, the file found must still have it; with ``all_files_read``,
    so must every file the readers follow (an OpenFAST deck's AeroDyn, blade and airfoil
    files), compared in reading order.

    Parameters
    ----------
    table : dict
        The recorded ``[rotor]`` table (absolute paths).
    provenance : dict or None
        The recorded files; None for results that recorded none (existence checked only).
    result_dir : str or Path or None
        The result's folder.
    source : str
        Named in errors (the result file).

    Returns
    -------
    RotorSource

    Raises
    ------
    InputError
        Naming the file: missing (with the places looked at) or changed since the run (both
        digests shortened); or any error of :func:`rotor_from_table`.
    """
    records = records_by_path(provenance)
    rdir = None if result_dir is None else Path(result_dir).resolve()
    if not isinstance(table, dict):
        raise InputError(f"expected the recorded [rotor] table, got {table!r}", source, None, "rotor")
    new, relocated = located_table(table, records, rdir, source)
    if provenance and provenance.get("all_files_read") and not relocated:
        # the files the readers follow, checked before reading where they were
        check_followed_files(records, source)
    out = rotor_from_table(new, source, None)
    if provenance and provenance.get("all_files_read"):
        check_files_read(provenance, out.files, source)
    return out
