"""Declarative mapping files: how the FMU adapter reaches a vendor's FMU in calib's terms.

A mapping (TOML, schema ``calib.fmu.mapping/1``, documented in ``fmu_models/README.md``)
names, per package quantity, the FMI variable that carries it and the conversion

.. math::
    y_{package} = s\\,(a\\,x_{FMU} + b) \\quad[\\bmod w], \\qquad
    x_{FMU} = (s\\,y_{package} - b)/a

with ``scale`` a, ``offset`` b, ``sign`` s = ±1 and ``wrap`` w (the entries, each with its
conversion both ways, are the data classes of :mod:`calib.fmu.mapping_entries`). Loading
validates the whole file against the schema: an unknown table or key, a missing required key
or a value of the wrong type is refused with :class:`~calib.errors.InputError` naming the file
and the key.
The ``[steady]`` and ``[jacobian]`` tables are read by :mod:`calib.fmu.rules` (their classes
:class:`~calib.fmu.rules.SteadyRule` and :class:`~calib.fmu.rules.JacobianRule`). Whether the named
variables exist in an FMU, with the right causality and variability, is checked by
:class:`calib.fmu.model.FmuModel` at load time (it has the FMU).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.config import NUM as _NUM, NUM_OR_BOOL, Key, check_table
from calib.errors import InputError, unknown_key
from calib.fmu.mapping_entries import (Corrections, Entry, OutputEntry, ParameterEntry, SettingEntry,
                                       SpanwiseOutput, Switch)
from calib.fmu.rules import JacobianRule, SteadyRule, jacobian_rule, steady_rule
from calib.tomlfile import read_toml
from calib.types import CONDITION_FIELDS, ParameterKind

SCHEMA = "calib.fmu.mapping/1"

#: Package units of the standard output names (other outputs declare ``channel_unit``).
OUTPUT_UNITS = {
    "power": "W", "thrust": "N", "torque": "N m", "azimuth": "deg", "rotor_speed": "rpm",
    "root_flap_moment": "N m", "root_edge_moment": "N m", "aero_failures": "-",
    **{f"root_{d}_moment_blade{n}": "N m" for d in ("flap", "edge") for n in (1, 2, 3)},
}
SPANWISE_OUTPUTS = {"normal_force": ("fn", "N/m"), "angle_of_attack": (None, "deg")}
SWITCH_EFFECTS = ("tip_loss", "hub_loss", "tower_shadow", "shear", "yaw", "skewed_wake", "dynamic_inflow",
                  "flexible_blades", "gravity", "stall_delay")

_TOP_KEYS = {"schema", "variant", "fmi_version", "model_identifier", "fmu_file", "description", "inputs",
             "outputs", "corrections", "parameters", "switches", "settings", "steady", "jacobian", "rotor"}
_ENTRY_KEYS = {"variable": Key(str, True), "element": Key(int), "unit": Key(str), "scale": Key(_NUM),
               "offset": Key(_NUM), "sign": Key(int), "wrap": Key(_NUM), "description": Key(str)}
_OUTPUT_KEYS = {**_ENTRY_KEYS, "channel_unit": Key(str)}
_SETTING_KEYS = {**_ENTRY_KEYS, "value": Key(NUM_OR_BOOL)}
_PARAMETER_KEYS = {**{k: v for k, v in _ENTRY_KEYS.items() if k != "scale"}, "conversion_scale": Key(_NUM),
                   "kind": Key(str), "nominal": Key(_NUM), "lower": Key(_NUM), "upper": Key(_NUM),
                   "scale": Key(_NUM, True), "prior_std": Key(_NUM), "package_unit": Key(str)}
_SPANWISE_KEYS = {"variables": Key(list), "variable": Key(str), "radius_variables": Key(list),
                  "radius_variable": Key(str), "unit": Key(str), "scale": Key(_NUM),
                  "offset": Key(_NUM), "description": Key(str)}
_CORRECTION_KEYS = {"grid": Key(str), "alpha_nodes_deg": Key(list), "eta_nodes": Key(list),
                    "layout": Key(str, True), "lift": Key(str, True), "drag": Key(str, True), "scale": Key(_NUM),
                    "cl_scale": Key(_NUM), "cd_scale": Key(_NUM), "cl_bound": Key(_NUM),
                    "cd_bound": Key(_NUM)}
_SWITCH_KEYS = {"variable": Key(str, True), "on": Key(NUM_OR_BOOL, True), "off": Key(NUM_OR_BOOL, True),
                "values": Key(dict), "description": Key(str)}


def _check_list(values, kind, where: str, source: str) -> None:
    """Every element of the array ``values`` is of ``kind`` (str, or numbers)."""
    numbers = kind is not str
    ok = all((isinstance(v, (int, float)) and not isinstance(v, bool)) if numbers else isinstance(v, str)
             for v in values)
    if not ok or not values:
        raise InputError(f"'{where}' must be a non-empty array of {'numbers' if numbers else 'names'}, got "
                         f"{values!r:.80}", source, field=where)


def _check(table, allowed: dict, where: str, source: str) -> None:
    check_table(table, allowed, where, source, table_label=f"'{where}'")


@dataclass(frozen=True)
class Mapping:
    """A validated mapping file (see the module docstring)."""

    source: str
    fmi_version: str | None
    model_identifier: str | None
    variant: str | None
    inputs: dict[str, Entry]
    outputs: dict[str, OutputEntry]
    spanwise: dict[str, SpanwiseOutput]
    corrections: Corrections | None
    parameters: dict[str, ParameterEntry]
    switches: dict[str, Switch]
    settings: dict[str, SettingEntry]
    steady: SteadyRule
    jacobian: JacobianRule
    rotor_radius: float | Entry | None
    directory: str = ""
    raw: dict = field(default_factory=dict, repr=False)

    @property
    def azimuth(self) -> OutputEntry | None:
        return self.outputs.get("azimuth")

    def to_dict(self) -> dict:
        """The file's content (JSON-able), e.g. to record it with a result."""
        return json.loads(json.dumps(self.raw))


def _entry(cls, name: str, e: dict, where: str, source: str, allowed: dict, **extra):
    _check(e, allowed, where, source)
    sign = int(e.get("sign", 1))
    if sign not in (1, -1):
        raise InputError(f"'{where}.sign' must be 1 or -1, got {sign}", source, field=f"{where}.sign")
    scale = float(e.get("conversion_scale" if cls is ParameterEntry else "scale", 1.0))
    if not np.isfinite(scale) or scale == 0.0:
        raise InputError(f"'{where}' conversion scale must be finite and non-zero, got {scale!r}", source,
                         field=where)
    if "element" in e and e["element"] < 0:
        raise InputError(f"'{where}.element' must be >= 0, got {e['element']}", source, field=f"{where}.element")
    wrap = e.get("wrap")
    if wrap is not None and not wrap > 0:
        raise InputError(f"'{where}.wrap' must be > 0, got {wrap!r}", source, field=f"{where}.wrap")
    return cls(name=name, variable=e["variable"], element=e.get("element"), scale=scale,
               offset=float(e.get("offset", 0.0)), sign=sign, wrap=float(wrap) if wrap else None,
               unit=e.get("unit", ""), description=e.get("description", ""), **extra)


def _inputs(data: dict, src: str):
    """``[inputs]``: the operating conditions the FMU takes (wind and rotor speed required)."""
    inputs = {}
    _check(data["inputs"], {f: Key(dict) for f in CONDITION_FIELDS}, "inputs", src)
    for name, e in data["inputs"].items():
        inputs[name] = _entry(Entry, name, e, f"inputs.{name}", src, _ENTRY_KEYS)
    for req in ("wind_speed", "rotor_speed"):
        if req not in inputs:
            raise InputError(f"missing required key 'inputs.{req}' (the steady window needs the rotor speed, "
                             "every operating point a wind speed)", src, field=f"inputs.{req}")
    return inputs


def _outputs(data: dict, src: str):
    """``[outputs]``: scalar outputs, and spanwise ones (``normal_force``, ``angle_of_attack``)."""
    outputs, spanwise = {}, {}
    for name, e in data["outputs"].items():
        where = f"outputs.{name}"
        if name in SPANWISE_OUTPUTS:
            _check(e, _SPANWISE_KEYS, where, src)
            if ("variables" in e) == ("variable" in e):
                raise InputError(f"'{where}' needs either 'variables' (scalars) or 'variable' (an array)", src,
                                 field=where)
            if "variables" in e and not all(isinstance(v, str) for v in e["variables"]):
                raise InputError(f"'{where}.variables' must be an array of names", src, field=f"{where}.variables")
            if "radius_variables" in e:
                _check_list(e["radius_variables"], str, f"{where}.radius_variables", src)
            spanwise[name] = SpanwiseOutput(name, tuple(e.get("variables", ())), e.get("variable"),
                                            tuple(e.get("radius_variables", ())), e.get("radius_variable"),
                                            float(e.get("scale", 1.0)), float(e.get("offset", 0.0)),
                                            e.get("unit", ""))
            continue
        if not isinstance(e, dict) or "variable" not in e:
            _check(e, _OUTPUT_KEYS, where, src)
        unit = e.get("channel_unit", OUTPUT_UNITS.get(name, "-"))
        outputs[name] = _entry(OutputEntry, name, e, where, src, _OUTPUT_KEYS, channel_unit=unit)
    return outputs, spanwise


def _corrections(data: dict, src: str):
    """``[corrections]``: the correction nodes the FMU exposes (None without the table)."""
    corrections = None
    if "corrections" in data:
        c = data["corrections"]
        _check(c, _CORRECTION_KEYS, "corrections", src)
        if c["layout"] not in ("scalar", "array"):
            raise InputError(f"'corrections.layout' must be \"scalar\" or \"array\", got {c['layout']!r}", src,
                             field="corrections.layout")
        if ("grid" in c) == ("alpha_nodes_deg" in c or "eta_nodes" in c):
            raise InputError("'corrections' needs either 'grid' (a JSON file inside the FMU) or 'alpha_nodes_deg' "
                             "and 'eta_nodes'", src, field="corrections.grid")
        if c["layout"] == "scalar":
            for block in ("lift", "drag"):
                if "{i}" not in c[block] or "{j}" not in c[block]:
                    raise InputError(f"'corrections.{block}' must be a name template with {{i}} (alpha node) and "
                                     f"{{j}} (eta node) for layout \"scalar\", got {c[block]!r}", src,
                                     field=f"corrections.{block}")
        for key in ("alpha_nodes_deg", "eta_nodes"):
            if key in c:
                _check_list(c[key], float, f"corrections.{key}", src)
        options = {k: float(c[k]) for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound") if k in c}
        corrections = Corrections(c["layout"], c["lift"], c["drag"], float(c.get("scale", 1.0)), c.get("grid"),
                                  tuple(c["alpha_nodes_deg"]) if "alpha_nodes_deg" in c else None,
                                  tuple(c["eta_nodes"]) if "eta_nodes" in c else None, options)
    return corrections


def _parameters(data: dict, src: str):
    """``[parameters]``: the tunable scalars, with nominal, bounds, scale, kind and prior."""
    parameters = {}
    for name, e in data.get("parameters", {}).items():
        where = f"parameters.{name}"
        _check(e, _PARAMETER_KEYS, where, src)
        kind = e.get("kind", "tuning")
        valid = [k.value for k in ParameterKind if k.value not in ("lift_correction", "drag_correction")]
        if kind not in valid:
            raise InputError(f"'{where}.kind' must be one of {', '.join(valid)}, got {kind!r}", src,
                             field=f"{where}.kind")
        if not e["scale"] > 0:
            raise InputError(f"'{where}.scale' (typical magnitude of a change, package units) must be > 0", src,
                             field=f"{where}.scale")
        parameters[name] = _entry(ParameterEntry, name, e, where, src, _PARAMETER_KEYS, kind=kind,
                                  nominal=float(e.get("nominal", np.nan)), lower=float(e.get("lower", np.nan)),
                                  upper=float(e.get("upper", np.nan)), typical=float(e["scale"]),
                                  prior_std=float(e.get("prior_std", np.nan)),
                                  package_unit=e.get("package_unit", e.get("unit", "-")))
    return parameters


def _switches(data: dict, src: str):
    """``[switches]``: effect switches and the FMU values that mean on, off or a model."""
    switches = {}
    for name, e in data.get("switches", {}).items():
        where = f"switches.{name}"
        _check(e, _SWITCH_KEYS, where, src)
        for model, value in e.get("values", {}).items():
            if not isinstance(value, (int, float, bool)):
                raise InputError(f"'{where}.values.{model}' must be a number or true/false (the FMU value of that "
                                 f"model), got {value!r}", src, field=f"{where}.values.{model}")
        switches[name] = Switch(name, e["variable"], e["on"], e["off"], dict(e.get("values", {})))
    return switches


def _settings(data: dict, src: str):
    """``[settings]``: fixed FMU parameters with their default values."""
    settings = {}
    for name, e in data.get("settings", {}).items():
        _check(e, _SETTING_KEYS, f"settings.{name}", src)
        settings[name] = _entry(SettingEntry, name, e, f"settings.{name}", src, _SETTING_KEYS, value=e.get("value"))
    return settings


def _rotor_radius(data: dict, src: str):
    """``[rotor] radius``: a number [m] or an output entry (None without the table)."""
    radius = None
    if "rotor" in data:
        _check(data["rotor"], {"radius": Key((int, float, dict), True)}, "rotor", src)
        r = data["rotor"]["radius"]
        radius = (float(r) if not isinstance(r, dict) else
                  _entry(Entry, "rotor_radius", r, "rotor.radius", src, _ENTRY_KEYS))
        if isinstance(radius, float) and not radius > 0:
            raise InputError(f"'rotor.radius' must be > 0 m, got {radius!r}", src, field="rotor.radius")
    return radius


def load_mapping(path) -> Mapping:
    """Read and validate a mapping file.

    Parameters
    ----------
    path : str or Path
        The mapping TOML file.

    Returns
    -------
    Mapping

    Raises
    ------
    InputError
        File missing or not TOML (line and column named), wrong ``schema``, unknown table or
        key, missing required key, wrong type, invalid value (each naming file and key).
    """
    path = Path(path)
    src = str(path)
    data = read_toml(path, "mapping file", finite=True)  # no value is NaN/inf (leave a key out for "the FMU's")
    for key in data:
        if key not in _TOP_KEYS:
            raise InputError(unknown_key(key, sorted(_TOP_KEYS)), src, field=key)
    if data.get("schema") != SCHEMA:
        raise InputError(f"'schema' must be \"{SCHEMA}\", got {data.get('schema')!r}", src, field="schema")
    for key in ("variant", "fmi_version", "model_identifier", "fmu_file", "description"):
        if key in data and not isinstance(data[key], str):
            raise InputError(f"'{key}' must be a string, got {data[key]!r}", src, field=key)
    if data.get("fmi_version") not in (None, "2.0", "3.0"):
        raise InputError(f"'fmi_version' must be \"2.0\" or \"3.0\", got {data['fmi_version']!r}", src,
                         field="fmi_version")
    for table in ("inputs", "outputs", "steady"):
        if table not in data:
            raise InputError(f"missing required table [{table}]", src, field=table)
    for table in ("inputs", "outputs", "corrections", "parameters", "switches", "settings", "steady", "jacobian",
                  "rotor"):
        if table in data and not isinstance(data[table], dict):
            raise InputError(f"[{table}] must be a table, got {data[table]!r:.60}", src, field=table)

    inputs = _inputs(data, src)              # the tables in this order: the first error found is reported
    outputs, spanwise = _outputs(data, src)
    return Mapping(src, data.get("fmi_version"), data.get("model_identifier"), data.get("variant"),
                   inputs, outputs, spanwise, _corrections(data, src), _parameters(data, src),
                   _switches(data, src), _settings(data, src), steady_rule(data["steady"], src),
                   jacobian_rule(data, src), _rotor_radius(data, src), str(path.parent), data)
