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

Provenance: every file a table's rotor was read from is remembered with its SHA-256 (taken
when read) and its path relative to the workflow's folder (:func:`recorded_rotor_files`,
which a model's ``spec()`` records in a result). A result written without its rotor data
rebuilds the rotor from those files (:func:`rotor_from_recorded_files`), refusing any that
is missing or changed since the run.
"""

from __future__ import annotations

import os
import reprlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.errors import InputError, unknown_key
from calib.measurements import sha256_of
from calib.rotor.aerodyn import read_aerodyn_main, rotor_from_aerodyn
from calib.rotor.geometry import Rotor
from calib.rotor.library import ROTORS, load_rotor
from calib.rotor.openfast import read_openfast
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
        name = table["name"]
        if not isinstance(name, str) or name.strip().lower() not in ROTORS:
            raise InputError(f"unknown rotor {name!r}; valid names: {', '.join(ROTORS)}", src, None, _key("name"))
        return RotorSource(rotor=load_rotor(name))

    if kind == "openfast":
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

    geometry = dict(hub_radius=setup.get("hub_radius"), n_blades=setup.get("n_blades"),
                    precone_deg=setup.get("precone"),
                    tilt_deg=setup.get("tilt"), hub_height=setup.get("hub_height"))

    if kind == "aerodyn":
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

    if kind == "aerodyn_blade":
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

    # windio
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


# ----------------------------------------------------------------------------- provenance
FILE_KEYS = ("openfast", "aerodyn", "aerodyn_blade", "windio")


def absolute_table(table: dict, base_dir) -> dict:
    """The ``[rotor]`` table with its file paths absolute and resolved (relative ones against
    ``base_dir``), the form a result records."""
    out = dict(table)
    base = Path(base_dir) if base_dir is not None else Path()
    for key in FILE_KEYS:
        if isinstance(out.get(key), str):
            out[key] = str((base / out[key]).resolve())
    if isinstance(out.get("airfoils"), list):
        out["airfoils"] = [str((base / a).resolve()) if isinstance(a, str) else a for a in out["airfoils"]]
    return out


def file_provenance(files, base_dir) -> dict:
    """Provenance of the files a rotor was read from (:attr:`RotorSource.files`), for a result.

    Parameters
    ----------
    files : sequence of path
        Every file read, in reading order (an OpenFAST deck's ElastoDyn, AeroDyn, blade and
        airfoil files too).
    base_dir : str or Path or None
        The workflow's folder, that relative paths are given against.

    Returns
    -------
    dict
        ``{"workflow_dir", "all_files_read": True, "files": [{"path", "relative", "sha256"}, ...]}``:
        absolute path, path relative to ``base_dir`` and SHA-256 of each file.
    """
    wdir = None if base_dir is None else str(Path(base_dir).resolve())
    out = []
    for f in files:
        path = str(Path(f).resolve())
        try:
            rel = os.path.relpath(path, wdir) if wdir is not None else None
        except ValueError:          # another drive (Windows)
            rel = None
        out.append({"path": path, "relative": rel, "sha256": sha256_of(path) if Path(path).is_file() else None})
    return {"workflow_dir": wdir, "all_files_read": True, "files": out}


def _named_files(table: dict) -> list[tuple[str, str]]:
    """(key, path) of the files a table names itself, in table order."""
    out = [(f"rotor.{k}", table[k]) for k in FILE_KEYS if isinstance(table.get(k), str)]
    if isinstance(table.get("airfoils"), list):
        out += [(f"rotor.airfoils[{i}]", a) for i, a in enumerate(table["airfoils"]) if isinstance(a, str)]
    return out


def recorded_rotor_files(table: dict | None, read: dict | None = None) -> dict | None:
    """Provenance of the files behind a rotor table, for a result to record.

    Parameters
    ----------
    table : dict or None
        A ``[rotor]`` table with absolute paths (as :func:`absolute_table` gives it).
    read : dict, optional
        The provenance taken when the rotor was read (:func:`file_provenance`): every file
        read, hashed then, with paths relative to the workflow's folder.

    Returns
    -------
    dict or None
        None for an embedded rotor (no files); ``read`` when given; otherwise the files the
        table names, hashed now (``sha256`` None for one that is missing), with
        ``relative`` and ``workflow_dir`` None and ``all_files_read`` false.
    """
    if not isinstance(table, dict):
        return None
    named = _named_files(table)
    if not named:
        return None
    if read is not None:
        return read
    files = []
    for _, value in named:
        path = Path(value).expanduser().resolve()
        files.append({"path": str(path), "relative": None, "sha256": sha256_of(path) if path.is_file() else None})
    return {"workflow_dir": None, "all_files_read": False, "files": files}


def _changed(path, recorded: str, now: str, source: str, key: str) -> InputError:
    return InputError(f"rotor file {path} changed since the run (SHA-256 {recorded[:12]}... recorded, {now[:12]}... "
                      "now); restore the file the run read, or run the calibration again", source, None, key)


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
    records = {}
    for rec in (provenance or {}).get("files") or []:
        if isinstance(rec, dict) and isinstance(rec.get("path"), str):
            records[rec["path"]] = rec
    rdir = None if result_dir is None else Path(result_dir).resolve()
    relocated = False

    def locate(value: str, key: str) -> str:
        nonlocal relocated
        rec = records.get(value) or records.get(str(Path(value).resolve())) or {}
        candidates = [Path(value)]
        if rdir is not None:
            if isinstance(rec.get("relative"), str):
                candidates.append(rdir / rec["relative"])
            candidates.append(rdir / Path(value).name)
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            also = "".join(f", {c}" for c in candidates[1:])
            raise InputError(f"rotor file {value} is missing (looked at {candidates[0]}{also}); this result records "
                             "no rotor data of its own, so its model needs the files the run read", source, None, key)
        relocated |= found != candidates[0]
        if isinstance(rec.get("sha256"), str):
            now = sha256_of(found)
            if now != rec["sha256"]:
                raise _changed(found, rec["sha256"], now, source, key)
        return str(found.resolve())

    if not isinstance(table, dict):
        raise InputError(f"expected the recorded [rotor] table, got {table!r}", source, None, "rotor")
    new = dict(table)
    for key in FILE_KEYS:
        if isinstance(new.get(key), str):
            new[key] = locate(new[key], f"rotor.{key}")
    if isinstance(new.get("airfoils"), list):
        new["airfoils"] = [locate(a, f"rotor.airfoils[{i}]") if isinstance(a, str) else a
                           for i, a in enumerate(new["airfoils"])]
    if provenance and provenance.get("all_files_read") and not relocated:
        # the files the readers follow, checked before reading where they were
        for rec in records.values():
            path = Path(rec["path"])
            if isinstance(rec.get("sha256"), str) and path.is_file():
                now = sha256_of(path)
                if now != rec["sha256"]:
                    raise _changed(path, rec["sha256"], now, source, "rotor")
    out = rotor_from_table(new, source, None)
    if provenance and provenance.get("all_files_read"):
        recorded = [r for r in provenance.get("files") or [] if isinstance(r, dict)]
        if len(recorded) != len(out.files):
            raise InputError(f"the rotor files now lead to {len(out.files)} files, the run read {len(recorded)} "
                             f"({', '.join(str(r.get('path')) for r in recorded)}): changed since the run", source,
                             None, "rotor")
        for rec, path in zip(recorded, out.files):
            if isinstance(rec.get("sha256"), str):
                now = sha256_of(path)
                if now != rec["sha256"]:
                    raise _changed(path, rec["sha256"], now, source, "rotor")
    return out
