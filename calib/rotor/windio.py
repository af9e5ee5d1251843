"""Reader for windIO turbine ontology files (IEA Wind Task 37), v1.x layout.

:func:`read_windio` turns ``components.blade.outer_shape_bem``, ``components.hub``,
``components.nacelle.drivetrain``, ``assembly``, ``control`` and the top-level
``airfoils`` into a :class:`~calib.rotor.geometry.Rotor`.

Conventions (checked against the AeroDyn files of the same turbines in the tests):

- ``reference_axis.z`` is the distance from the blade root along the pitch axis [m],
  so r = hub radius + z and the tip radius is hub radius + z(1).
- ``reference_axis.x`` (prebend): windIO, WISDEM (which writes AeroDyn ``BlCrvAC = x``)
  and AeroDyn agree that a negative value bends the blade upwind, away from the tower
  (IEA 3.4: x(tip) = BlCrvAC(tip) = -2.5 m). The Rotor stores precurve in the CCBlade
  convention (positive away from the tower), so ``precurve = -x``.
  ``reference_axis.y`` is stored as ``presweep``.
- ``twist`` is in radians in windIO and stored in degrees, positive toward feather.
- airfoils: each station takes the airfoil whose ``airfoil_position`` is nearest in
  the non-dimensional span coordinate (ties go inboard). WISDEM instead blends
  airfoil shapes and polars by relative thickness between the positions; the
  nearest-position rule keeps every station on a real, measured or published polar.

Reference: windIO ontology, https://github.com/IEAWindTask37/windIO (v1.0);
P. Bortolotti et al., IEA Wind TCP Task 37: Systems engineering in wind energy,
WP2.1 Reference wind turbines, NREL/TP-5000-73492 (2019).
"""

from __future__ import annotations

import reprlib
from pathlib import Path

import numpy as np
import yaml
from scipy.interpolate import PchipInterpolator

from calib.errors import InputError
from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import Airfoil, PolarTable
from calib.rotor.viterna import densify_full_circle

DEFAULT_N_STATIONS = 30
_RPM_PER_RAD_S = 30.0 / np.pi

try:  # the C loader is ~10x faster on the 200 kB turbine files
    _Loader = yaml.CSafeLoader
except AttributeError:  # pragma: no cover - depends on the libyaml build
    _Loader = yaml.SafeLoader


def load_windio(path) -> dict:
    """Parse a windIO yaml file into a dict (errors name the file and line)."""
    src = str(path)
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise InputError("file not found", src) from None
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror or exc})", src) from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        start = exc.start + (3 if raw.startswith(b"\xef\xbb\xbf") else 0)
        line = raw[:start].count(b"\n") + 1
        column = start - raw.rfind(b"\n", 0, start)
        raise InputError(f"not UTF-8 text: byte 0x{raw[start]:02x} at column {column} cannot be decoded; "
                         "expected a windIO YAML file in UTF-8", src, line) from None
    try:
        data = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        if line is None and isinstance(getattr(exc, "position", None), int):  # yaml.reader.ReaderError
            line = text.count("\n", 0, exc.position) + 1
        raise InputError(f"invalid YAML: {getattr(exc, 'problem', None) or exc}", src, line) from None
    except RecursionError:
        raise InputError("invalid YAML: nesting too deep", src) from None
    if not isinstance(data, dict):
        raise InputError(f"expected a mapping at the top level, got {type(data).__name__}", src)
    return data


_BRIEF = reprlib.Repr()
_BRIEF.maxstring = _BRIEF.maxother = 60


def _brief(value) -> str:
    """A short repr for messages (reprlib: bounded even for YAML aliases nested into billions of items)."""
    return _BRIEF.repr(value)


def _get(data, keys: str, src: str):
    node = data
    for key in keys.split("."):
        if not isinstance(node, dict) or key not in node:
            raise InputError(f"missing key {key!r}", src, field=keys)
        node = node[key]
    return node


def _table(data, keys: str, src: str, default=None) -> dict:
    """The mapping at ``keys`` (``default`` when a key on the way is absent or null)."""
    node = data
    for k, key in enumerate(keys.split(".")):
        if not isinstance(node, dict):
            raise InputError(f"expected a mapping, got {_brief(node)}", src, field=".".join(keys.split(".")[:k]))
        node = node.get(key)
        if node is None:
            if default is None:
                raise InputError(f"missing key {key!r}", src, field=keys)
            return default
    if not isinstance(node, dict):
        raise InputError(f"expected a mapping, got {_brief(node)}", src, field=keys)
    return node


def _float(value, key: str, src: str, positive: bool = False) -> float:
    """A finite number (> 0 when ``positive``); errors name the key."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"expected a number, got {_brief(value)}", src, field=key)
    try:
        out = float(value)
    except OverflowError:
        out = float("inf")
    if not np.isfinite(out) or (positive and out <= 0):
        raise InputError(f"expected a finite {'positive ' if positive else ''}number, got {_brief(value)}", src,
                         field=key)
    return out


def _is_number_list(value) -> bool:
    """A flat list of numbers (checked before numpy sees it: YAML aliases can nest a list
    of lists into billions of elements in a few lines)."""
    return isinstance(value, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in value)


def _curve(data, keys: str, src: str):
    node = _get(data, keys, src)
    if not isinstance(node, dict) or not all(_is_number_list(node.get(k)) for k in ("grid", "values")):
        raise InputError(f"expected a mapping with 'grid' and 'values' lists of numbers, got {_brief(node)}", src,
                         field=keys)
    grid = np.asarray(node["grid"], dtype=float)
    values = np.asarray(node["values"], dtype=float)
    if grid.shape != values.shape or grid.ndim != 1 or grid.size < 2:
        raise InputError(f"'grid' and 'values' must be 1-D of equal length >= 2, got {grid.shape} and "
                         f"{values.shape}", src, field=keys)
    if not (np.all(np.isfinite(grid)) and np.all(np.isfinite(values))):
        raise InputError("grid and values must be finite numbers", src, field=keys)
    if np.any(np.diff(grid) <= 0):
        raise InputError("grid must be strictly increasing", src, field=keys)
    return grid, values


def _sample(data, keys, src, s):
    grid, values = _curve(data, keys, src)
    if grid[0] > s[0] + 1e-9 or grid[-1] < s[-1] - 1e-9:
        raise InputError(f"grid covers [{grid[0]:g}, {grid[-1]:g}], stations need [{s[0]:g}, {s[-1]:g}]",
                         src, field=keys)
    with np.errstate(all="ignore"):  # huge values overflow: refused just below, without warnings
        out = PchipInterpolator(grid, values)(s)
    if not np.all(np.isfinite(out)):
        raise InputError("values too large: the interpolated curve is not finite", src, field=keys)
    return out


def nearest_airfoil_labels(positions, labels, s) -> list[str]:
    """Label of the nearest ``airfoil_position`` for every station.

    Parameters
    ----------
    positions : array_like, shape (n_positions,)
        Non-dimensional span positions of the labelled airfoils [-], increasing.
    labels : sequence of str, shape (n_positions,)
    s : array_like, shape (n_stations,)
        Non-dimensional span of the stations [-].

    Returns
    -------
    list of str
        Ties (a station midway between two positions) go to the inboard airfoil.
    """
    positions = np.asarray(positions, dtype=float)
    dist = np.abs(np.asarray(s, dtype=float)[:, None] - positions[None, :])
    return [labels[int(k)] for k in np.argmin(dist + 1e-12 * np.arange(positions.size), axis=1)]


def windio_airfoil(entry: dict, src: str) -> Airfoil:
    """An :class:`Airfoil` from one entry of the top-level ``airfoils`` list.

    Every polar (several Reynolds numbers possible) becomes a table; angles are
    converted from rad to deg, c_d and c_m are interpolated on the c_l grid. When
    several polars share one Reynolds number (different ``configuration``), the
    first is kept.
    """
    if not isinstance(entry, dict):
        raise InputError(f"expected a mapping (name, polars ...), got {_brief(entry)}", src, field="airfoils")
    name = entry.get("name", "?")
    polars = entry.get("polars") or []
    if not isinstance(polars, list):
        raise InputError(f"expected a list of polars, got {_brief(polars)}", src, field=f"airfoils[{name}].polars")
    tables, seen = [], set()
    for k, polar in enumerate(polars):
        where = f"airfoils[{name}].polars[{k}]"
        if not isinstance(polar, dict):
            raise InputError(f"expected a mapping (re, c_l, c_d ...), got {_brief(polar)}", src, field=where)
        re_ = float("nan") if polar.get("re") is None else _float(polar["re"], f"{where}.re", src, positive=True)
        if re_ in seen:
            continue
        seen.add(re_)
        a_l, cl = _curve(polar, "c_l", src)
        a_d, cd = _curve(polar, "c_d", src)
        cm = None
        if "c_m" in polar:
            a_m, cm_v = _curve(polar, "c_m", src)
            cm = np.interp(a_l, a_m, cm_v)
        alpha = np.degrees(a_l)
        cd = np.interp(a_l, a_d, cd)
        alpha, cl, cd, cm = densify_full_circle(alpha, cl, cd, cm)
        tables.append(PolarTable(alpha, cl, cd, cm, re_, source=f"{src}: {where}"))
    if not tables:
        raise InputError("airfoil has no polars", src, field=f"airfoils[{name}].polars")
    thickness = entry.get("relative_thickness")
    thickness = float("nan") if thickness is None else _float(thickness, f"airfoils[{name}].relative_thickness",
                                                                src, positive=True)
    return Airfoil(str(name), tuple(tables), thickness)


def windio_schedule(data: dict, source: str = "<windIO>",
                    generator_efficiency: float | None = None) -> OperatingSchedule | None:
    """Steady control schedule from the ``control`` and ``assembly`` sections.

    Parameters
    ----------
    data : dict
        Parsed windIO file (:func:`load_windio`).
    source : str
        File name for error messages.
    generator_efficiency : float, optional
        Electrical / aerodynamic power [-]; default 1. The rated power in windIO is
        electrical; the schedule's aerodynamic rated power is rated / efficiency [W].

    Returns
    -------
    OperatingSchedule or None
        Rotor-speed limits from ``minOmega``/``maxOmega`` (or ``VS_minspd``/``VS_maxspd``)
        [rad/s -> rpm], TSR from ``torque.tsr``, fine pitch ``pitch.min_pitch``
        [rad -> deg], cut-in/out ``Vin``/``Vout`` [m/s]. None when a value is missing.
    """
    src = source
    sup = _table(data, "control.supervisory", src, {})
    torque = _table(data, "control.torque", src, {})
    pitch = _table(data, "control.pitch", src, {})
    assembly = _table(data, "assembly", src, {})
    rated = assembly.get("rated_power", sup.get("rated_power"))
    w_min = sup.get("minOmega", torque.get("VS_minspd"))
    w_max = sup.get("maxOmega", torque.get("VS_maxspd"))
    tsr = torque.get("tsr")
    if None in (rated, w_min, w_max, tsr):
        return None
    rated_key = "assembly.rated_power" if "rated_power" in assembly else "control.supervisory.rated_power"
    w_min_key = "control.supervisory.minOmega" if "minOmega" in sup else "control.torque.VS_minspd"
    w_max_key = "control.supervisory.maxOmega" if "maxOmega" in sup else "control.torque.VS_maxspd"
    rated = _float(rated, rated_key, src, positive=True)
    w_min, w_max = _float(w_min, w_min_key, src), _float(w_max, w_max_key, src)
    if not 0 <= w_min <= w_max:
        raise InputError(f"rotor-speed limits must satisfy 0 <= min <= max, got {w_min:g} and {w_max:g} rad/s",
                         src, field=w_min_key)
    eff = 1.0 if generator_efficiency is None else float(generator_efficiency)
    if not 0 < eff <= 1:
        raise InputError(f"must be in (0, 1], got {generator_efficiency!r}", src, field="generator_efficiency")
    cut_in = _float(sup.get("Vin", 3.0), "control.supervisory.Vin", src)
    cut_out = _float(sup.get("Vout", 25.0), "control.supervisory.Vout", src)
    return OperatingSchedule(rated_power=rated / eff, min_rotor_speed=w_min * _RPM_PER_RAD_S,
                             max_rotor_speed=w_max * _RPM_PER_RAD_S,
                             design_tsr=_float(tsr, "control.torque.tsr", src, positive=True),
                             fine_pitch=float(np.degrees(_float(pitch.get("min_pitch", 0.0),
                                                                "control.pitch.min_pitch", src))),
                             cut_in=cut_in, cut_out=cut_out, generator_efficiency=eff)


def windio_rotor_setup(data: dict, source: str = "<windIO>") -> dict:
    """Hub and orientation data of a parsed windIO file.

    Returns
    -------
    dict
        ``hub_radius`` = hub diameter / 2 [m], ``n_blades``, ``precone_deg`` = hub
        ``cone_angle`` [rad -> deg], ``tilt_deg`` = drivetrain ``uptilt`` (or
        ``uptilt_angle``) [rad -> deg], ``hub_height`` [m].
    """
    src = source
    drivetrain = _table(data, "components.nacelle.drivetrain", src, {})
    tilt_key = "uptilt" if "uptilt" in drivetrain else "uptilt_angle"
    tilt = drivetrain.get(tilt_key)
    if tilt is None:
        raise InputError("missing key 'uptilt'", src, field="components.nacelle.drivetrain.uptilt")
    n_key = "assembly.number_of_blades"
    n_blades = _float(_get(data, n_key, src), n_key, src, positive=True)
    if n_blades != int(n_blades):
        raise InputError(f"expected an integer number of blades, got {n_blades:g}", src, field=n_key)
    return {"hub_radius": 0.5 * _float(_get(data, "components.hub.diameter", src), "components.hub.diameter", src,
                                       positive=True),
            "n_blades": int(n_blades),
            "precone_deg": float(np.degrees(_float(_get(data, "components.hub.cone_angle", src),
                                                   "components.hub.cone_angle", src))),
            "tilt_deg": float(np.degrees(_float(tilt, f"components.nacelle.drivetrain.{tilt_key}", src))),
            "hub_height": _float(_get(data, "assembly.hub_height", src), "assembly.hub_height", src, positive=True)}


def read_windio(path, n_stations: int = DEFAULT_N_STATIONS, *, name: str | None = None,
                generator_efficiency: float | None = None) -> Rotor:
    """Read a windIO turbine file into a :class:`Rotor`.

    Parameters
    ----------
    path : str or Path
        windIO yaml file.
    n_stations : int, default 30
        Number of blade stations, equally spaced in the non-dimensional span
        coordinate from root (0) to tip (1), like the AeroDyn files of the IEA turbines.
    name : str, optional
        Rotor name; default the file stem.
    generator_efficiency : float, optional
        Electrical / aerodynamic power [-]. windIO gives the *electrical* rated power;
        the schedule's (aerodynamic) rated power is that divided by this efficiency.
        Default 1.

    Returns
    -------
    Rotor
        r = hub_radius + z [m]; chord [m] and twist [deg] by PCHIP interpolation (as
        WISDEM); precurve = -reference_axis.x, presweep = reference_axis.y [m];
        hub radius = hub diameter / 2 [m]; precone = hub cone_angle [deg]; tilt =
        drivetrain uptilt [deg]; the schedule from ``control`` (None when incomplete).
    """
    src = str(path)
    if int(n_stations) < 2:
        raise InputError(f"n_stations must be >= 2, got {n_stations}", src, field="n_stations")
    data = load_windio(path)
    bem = "components.blade.outer_shape_bem"
    s = np.linspace(0.0, 1.0, int(n_stations))
    chord = _sample(data, f"{bem}.chord", src, s)
    twist = np.degrees(_sample(data, f"{bem}.twist", src, s))
    z = _sample(data, f"{bem}.reference_axis.z", src, s)
    x = _sample(data, f"{bem}.reference_axis.x", src, s)
    y = _sample(data, f"{bem}.reference_axis.y", src, s)
    setup = windio_rotor_setup(data, src)
    key = f"{bem}.airfoil_position"
    position = _table(data, key, src)
    grid, names = position.get("grid"), position.get("labels")
    if not (_is_number_list(grid) and isinstance(names, list) and len(grid) == len(names) >= 1
            and all(isinstance(x, str) for x in names)):
        raise InputError(f"expected 'grid' (numbers) and 'labels' (airfoil names) lists of equal length, got "
                         f"{_brief(position)}", src, field=key)
    grid = np.asarray(grid, dtype=float)
    if not np.all(np.isfinite(grid)):
        raise InputError("'grid' must be finite numbers", src, field=f"{key}.grid")
    labels = nearest_airfoil_labels(grid, names, s)
    listed = _get(data, "airfoils", src)
    if not isinstance(listed, list) or not all(isinstance(a, dict) for a in listed):
        raise InputError(f"expected a list of airfoils (mappings with name and polars), got {_brief(listed)}", src,
                         field="airfoils")
    for k, a in enumerate(listed):
        if not isinstance(a.get("name"), str):
            raise InputError(f"expected an airfoil name (a string), got {_brief(a.get('name'))}", src,
                             field=f"airfoils[{k}].name")
    entries = {a.get("name"): a for a in listed}
    used = list(dict.fromkeys(labels))
    missing = [lab for lab in used if lab not in entries]
    if missing:
        raise InputError(f"airfoil {missing[0]!r} of airfoil_position.labels is not in 'airfoils' "
                         f"(known: {sorted(entries)})", src, field=f"{bem}.airfoil_position.labels")
    airfoils = tuple(windio_airfoil(entries[lab], src) for lab in used)
    ids = np.array([used.index(lab) for lab in labels])
    return Rotor(name=name or Path(path).stem, r=setup["hub_radius"] + z, chord=chord, twist_deg=twist,
                 airfoil_id=ids, airfoils=airfoils, tip_radius=setup["hub_radius"] + z[-1], **setup,
                 precurve=-x, presweep=y, precurve_tip=-float(x[-1]), presweep_tip=float(y[-1]),
                 schedule=windio_schedule(data, src, generator_efficiency), source=src)
