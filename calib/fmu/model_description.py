"""Variable specs of the FMU variants -> ``modelDescription.xml`` and the C value-reference table.

Each variant declares its variables in ``fmu_models/<variant>/variables.toml`` (schema in
``fmu_models/README.md``). This module expands that declaration for one rotor and
correction grid (one scalar per node or one array, one variable per blade or an array,
...), assigns value references, and renders

- ``modelDescription.xml`` (FMI 2.0 or 3.0), and
- ``fmu_variables.h``, the table the C wrappers use to map value references to core
  variables with the unit map ``fmu = scale * core + offset``.

The core variable ids (``CV_*``) are parsed from ``fmu_models/core/rotor_core.h`` so a
spec that names an unknown core variable fails here, at build time, with its name.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from calib.errors import InputError, unknown_key

KINDS = ("input", "tunable", "fixed", "output")
TYPES = ("Real", "Integer", "Boolean")
EXPANSIONS = ("nodes", "blades", "out_stations")
MAX_BLADES = 3

#: Log categories of both FMUs (the same names, in this order, as LOG_CATEGORY in
#: fmu_models/core/fmu_slave.c): written into ``<LogCategories>`` of the model descriptions.
LOG_CATEGORIES = (
    ("logEvents", "Life-cycle events (initialization); off unless logging is on"),
    ("logStatusWarning", "Warnings"),
    ("logStatusError", "Refused calls and failures: the variable and its range, the time, the state"),
)

#: Units known to the generator: name -> (SI base-unit exponents, factor, offset)
UNITS = {
    "m/s": ({"m": 1, "s": -1}, 1.0), "rpm": ({"rad": 1, "s": -1}, math.pi / 30.0),
    "rad/s": ({"rad": 1, "s": -1}, 1.0), "deg": ({"rad": 1}, math.pi / 180.0),
    "kg/m3": ({"kg": 1, "m": -3}, 1.0), "Hz": ({"s": -1}, 1.0), "kg": ({"kg": 1}, 1.0),
    "t": ({"kg": 1}, 1000.0), "m": ({"m": 1}, 1.0), "s": ({"s": 1}, 1.0),
    "W": ({"kg": 1, "m": 2, "s": -3}, 1.0), "kW": ({"kg": 1, "m": 2, "s": -3}, 1000.0),
    "N": ({"kg": 1, "m": 1, "s": -2}, 1.0), "kN": ({"kg": 1, "m": 1, "s": -2}, 1000.0),
    "N.m": ({"kg": 1, "m": 2, "s": -2}, 1.0), "kN.m": ({"kg": 1, "m": 2, "s": -2}, 1000.0),
    "N/m": ({"kg": 1, "s": -2}, 1.0), "kN/m": ({"kg": 1, "s": -2}, 1000.0),
}


def core_variable_ids(header: Path) -> dict[str, int]:
    """``{"WIND_SPEED": 0, ...}`` from the ``CoreVar`` enum of ``rotor_core.h``."""
    text = header.read_text()
    body = text[text.index("typedef enum {"):text.index("} CoreVar;")]
    names = re.findall(r"^\s*CV_([A-Z0-9_]+)", body, flags=re.M)
    return {n: i for i, n in enumerate(names) if n != "COUNT"}


@dataclass
class FmuVariable:
    """One FMI variable after expansion."""

    name: str
    vr: int
    core: str
    index: int
    count: int
    kind: str
    type: str
    unit: str | None
    scale: float
    offset: float
    wrap360: bool
    start: list = field(default_factory=list)
    description: str = ""
    array: str | None = None
    min: float | None = None    # accepted range in FMU units (inputs and parameters)
    max: float | None = None


@dataclass
class VariantSpec:
    """The ``[fmu]`` table and the expanded variables of one variant."""

    fmi_version: str
    model_identifier: str
    model_name: str
    wrapper: str
    description: str
    variables: list[FmuVariable]


def _check_keys(table: dict, allowed: set, where: str):
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise InputError(unknown_key(unknown[0], sorted(allowed), label="allowed")
                         + (f" (also unknown: {', '.join(unknown[1:])})" if len(unknown) > 1 else ""), where)


def load_spec(path: Path, core_ids: dict[str, int], *, n_nodes: int, alpha_nodes, eta_nodes,
              out_radius, out_eta, rotor_facts: dict) -> VariantSpec:
    """Read and expand a variant's ``variables.toml``.

    Parameters
    ----------
    path : Path
        The spec file.
    core_ids : dict
        Core variable ids (:func:`core_variable_ids`).
    n_nodes : int
        Lift nodes of the correction grid (= drag nodes).
    alpha_nodes, eta_nodes : sequence of float
        Node locations [deg], [-] (for names and descriptions).
    out_radius, out_eta : sequence of float
        Radii [m] and r/R [-] of the spanwise output stations.
    rotor_facts : dict
        Values for ``start = "@rotor.<name>"``.
    """
    doc, fmu = _read_spec_file(path)
    counts = {"nodes": n_nodes, "blades": MAX_BLADES, "out_stations": len(out_radius)}
    out: list[FmuVariable] = []
    vr = 1
    for k, v in enumerate(doc.get("variable", [])):
        where = f"{path} variable #{k + 1} ({v.get('name', '?')})"
        common, start = _checked_fields(v, core_ids, rotor_facts, where)
        expand, array = _layout(v, fmu["fmi_version"], where)
        desc = v.get("description", "")
        if expand:
            for e in range(counts[expand]):
                labels = _labels(expand, e, alpha_nodes, eta_nodes, out_radius, out_eta)
                out.append(FmuVariable(name=v["name"].format(**labels), vr=vr, index=e, count=1,
                                       start=[] if start is None else [start],
                                       description=desc.format(**labels), **common))
                vr += 1
        else:
            n = counts[array] if array else 1
            if array == "out_stations":
                desc += " (r = " + ", ".join(f"{x:.3f}" for x in out_radius) + " m)"
            out.append(FmuVariable(name=v["name"], vr=vr, index=0, count=n,
                                   start=[] if start is None else [start] * n,
                                   description=desc, array=array, **common))
            vr += 1
    names = [x.name for x in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise InputError(f"duplicate variable names: {', '.join(dup)}", path)
    return VariantSpec(fmu["fmi_version"], fmu["model_identifier"], fmu["model_name"], fmu["wrapper"],
                       fmu.get("description", ""), out)


def _read_spec_file(path: Path) -> tuple[dict, dict]:
    """The TOML content of a ``variables.toml`` and its checked ``[fmu]`` table.

    Parameters
    ----------
    path : Path
        The spec file.

    Returns
    -------
    doc : dict
        The whole file (only ``[fmu]`` and ``[[variable]]`` allowed).
    fmu : dict
        ``[fmu]``, with ``fmi_version`` ("2.0" or "3.0"), ``model_identifier``, ``model_name``, ``wrapper``.
    """
    with open(path, "rb") as fh:
        try:
            doc = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"invalid TOML: {exc}", path) from None
    _check_keys(doc, {"fmu", "variable"}, str(path))
    fmu = doc.get("fmu", {})
    _check_keys(fmu, {"fmi_version", "model_identifier", "model_name", "wrapper", "description"},
                f"{path} [fmu]")
    for key in ("fmi_version", "model_identifier", "model_name", "wrapper"):
        if key not in fmu:
            raise InputError(f"[fmu] needs '{key}'", path, field=key)
    if fmu["fmi_version"] not in ("2.0", "3.0"):
        raise InputError(f"fmi_version must be '2.0' or '3.0', got {fmu['fmi_version']!r}", path,
                         field="fmi_version")
    return doc, fmu


def _checked_fields(v: dict, core_ids: dict[str, int], rotor_facts: dict,
                    where: str) -> tuple[dict, float | None]:
    """The fields every expansion of one ``[[variable]]`` shares, and its start value, checked.

    Parameters
    ----------
    v : dict
        The ``[[variable]]`` table.
    core_ids : dict
        Core variable ids (:func:`core_variable_ids`).
    rotor_facts : dict
        Values for ``start = "@rotor.<name>"``.
    where : str
        The variable in messages.

    Returns
    -------
    common : dict
        ``core``, ``kind``, ``type``, ``unit``, ``scale``, ``offset`` (FMU = scale · core + offset),
        ``wrap360``, ``min``, ``max`` [FMU units] of :class:`FmuVariable`.
    start : float or None
        Start value [FMU units] (None for an output without one).
    """
    allowed = {"name", "core", "kind", "type", "unit", "scale", "offset", "wrap360", "start",
               "description", "expand", "array", "min", "max"}
    _check_keys(v, allowed, where)
    for key in ("name", "core", "kind"):
        if key not in v:
            raise InputError(f"missing '{key}'", where, field=key)
    if v["core"] not in core_ids:
        raise InputError(f"unknown core variable {v['core']!r}; valid: {', '.join(core_ids)}",
                         where, field="core")
    if v["kind"] not in KINDS:
        raise InputError(f"kind must be one of {', '.join(KINDS)}", where, field="kind")
    vtype = v.get("type", "Real")
    if vtype not in TYPES:
        raise InputError(f"type must be one of {', '.join(TYPES)}", where, field="type")
    unit = v.get("unit")
    if unit is not None and unit not in UNITS:
        raise InputError(f"unknown unit {unit!r}; known: {', '.join(UNITS)}", where, field="unit")
    start = _start_value(v, rotor_facts, where)
    vmin, vmax = _range(v, vtype, start, where)
    common = dict(core=v["core"], kind=v["kind"], type=vtype, unit=unit,
                  scale=float(v.get("scale", 1.0)), offset=float(v.get("offset", 0.0)),
                  wrap360=bool(v.get("wrap360", False)), min=vmin, max=vmax)
    return common, start


def _start_value(v: dict, rotor_facts: dict, where: str) -> float | None:
    """The ``start`` of a variable [FMU units]: a number, or ``"@rotor.<name>"`` from ``rotor_facts``;
    required for inputs and parameters (None for an output without one)."""
    start = v.get("start")
    if v["kind"] != "output" and start is None:
        raise InputError("inputs and parameters need a start value", where, field="start")
    if isinstance(start, str):
        if not start.startswith("@rotor.") or start[7:] not in rotor_facts:
            raise InputError(f"start {start!r}: use a number or @rotor.<{'|'.join(rotor_facts)}>",
                             where, field="start")
        start = rotor_facts[start[7:]]
    if isinstance(start, bool):
        start = float(start)
    return start


def _layout(v: dict, fmi_version: str, where: str) -> tuple[str | None, str | None]:
    """``expand`` (one scalar per node, blade or output station) or ``array`` (one FMI 3 array) of a
    variable, at most one of them (None, None: one scalar)."""
    expand, array = v.get("expand"), v.get("array")
    if expand and array:
        raise InputError("use either 'expand' or 'array'", where)
    if (expand or array) and (expand or array) not in EXPANSIONS:
        raise InputError(f"expand/array must be one of {', '.join(EXPANSIONS)}", where)
    if array and fmi_version != "3.0":
        raise InputError("array variables need FMI 3.0", where, field="array")
    return expand, array


def _labels(expand: str, e: int, alpha_nodes, eta_nodes, out_radius, out_eta) -> dict:
    """Name and description fields of the ``e``-th expansion of a variable.

    Parameters
    ----------
    expand : str
        ``"nodes"`` (fields ``i``, ``j``, ``alpha`` [deg], ``eta`` [-]), ``"blades"`` (``n``) or
        ``"out_stations"`` (``k``, ``r`` [m], ``eta`` [-]).
    e : int
        0-based expansion index (node ``e`` runs over eta fastest).
    alpha_nodes, eta_nodes : sequence of float
        Node locations [deg], [-].
    out_radius, out_eta : sequence of float
        Radii [m] and r/R [-] of the spanwise output stations.
    """
    if expand == "nodes":
        i, j = divmod(e, len(eta_nodes))
        return dict(i=i, j=j, alpha=f"{alpha_nodes[i]:g}", eta=f"{eta_nodes[j]:g}")
    if expand == "blades":
        return dict(n=e + 1)
    return dict(k=e + 1, r=f"{out_radius[e]:.3f}", eta=f"{out_eta[e]:.3f}")


def _range(v: dict, vtype: str, start, where: str) -> tuple[float | None, float | None]:
    """The ``min``/``max`` of a variable: required for Real and Integer inputs and parameters,
    not allowed on outputs and Booleans; ``min <= start <= max``."""
    has = [k for k in ("min", "max") if k in v]
    if v["kind"] == "output" or vtype == "Boolean":
        if has:
            raise InputError(f"'{has[0]}' is only for Real and Integer inputs and parameters", where,
                             field=has[0])
        return None, None
    if len(has) != 2:
        raise InputError("inputs and parameters need a range: 'min' and 'max' in the FMU's units", where,
                         field="min" if "min" not in v else "max")
    lo, hi = v["min"], v["max"]
    for key, x in (("min", lo), ("max", hi)):
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise InputError(f"{key} must be a finite number, got {x!r}", where, field=key)
        if vtype == "Integer" and float(x) != int(x):
            raise InputError(f"{key} of an Integer must be an integer, got {x!r}", where, field=key)
    if not lo <= hi:
        raise InputError(f"min {lo!r} > max {hi!r}", where, field="min")
    if not lo <= float(start) <= hi:
        raise InputError(f"start {start!r} lies outside [min, max] = [{lo!r}, {hi!r}]", where, field="start")
    return float(lo), float(hi)


# ---------------------------------------------------------------------------- rendering
def _fmt(x: float, vtype: str, fmi3: bool) -> str:
    if vtype == "Boolean":
        return "true" if float(x) != 0.0 else "false"
    if vtype == "Integer":
        return str(int(round(float(x))))
    return repr(float(x))


def _unit_xml(units: set[str]) -> str:
    rows = []
    for name in sorted(units):
        exps, factor = UNITS[name]
        attrs = " ".join(f'{k}="{v}"' for k, v in exps.items())
        fac = f' factor="{factor!r}"' if factor != 1.0 else ""
        rows.append(f'    <Unit name={quoteattr(name)}><BaseUnit {attrs}{fac}/></Unit>')
    return "  <UnitDefinitions>\n" + "\n".join(rows) + "\n  </UnitDefinitions>\n" if rows else ""


def _log_categories_xml() -> str:
    rows = "".join(f"    <Category name={quoteattr(n)} description={quoteattr(d)}/>\n" for n, d in LOG_CATEGORIES)
    return f"  <LogCategories>\n{rows}  </LogCategories>\n"


def _causality(v: FmuVariable) -> tuple[str, str]:
    if v.kind == "input":
        return "input", ("continuous" if v.type == "Real" else "discrete")
    if v.kind == "output":
        return "output", ("continuous" if v.type == "Real" else "discrete")
    return "parameter", v.kind


def render_fmi2(spec: VariantSpec, guid: str, *, default_stop: float = 60.0,
                default_step: float = 0.05) -> str:
    units = {v.unit for v in spec.variables if v.unit}
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    head = (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(spec.model_name)} '
            f'guid="{guid}" description={quoteattr(spec.description)} generationTool="calib.fmu.build" '
            f'generationDateAndTime="{now}" variableNamingConvention="flat" numberOfEventIndicators="0">\n'
            f'  <CoSimulation modelIdentifier="{spec.model_identifier}" '
            f'canHandleVariableCommunicationStepSize="true" canGetAndSetFMUstate="true" '
            f'canSerializeFMUstate="true" canNotUseMemoryManagementFunctions="true"/>\n')
    body = [_unit_xml(units), _log_categories_xml(),
            f'  <DefaultExperiment startTime="0" stopTime="{default_stop:g}" stepSize="{default_step:g}"/>\n',
            "  <ModelVariables>\n"]
    outputs = []
    for pos, v in enumerate(spec.variables, start=1):
        caus, var = _causality(v)
        attrs = f'name={quoteattr(v.name)} valueReference="{v.vr}" causality="{caus}" variability="{var}"'
        if caus == "parameter":
            attrs += ' initial="exact"'
        if v.description:
            attrs += f" description={quoteattr(v.description)}"
        inner = ""
        if v.start:
            inner += f' start="{_fmt(v.start[0], v.type, False)}"'
        if v.min is not None:
            inner += f' min="{_fmt(v.min, v.type, False)}" max="{_fmt(v.max, v.type, False)}"'
        if v.unit and v.type == "Real":
            inner += f' unit="{escape(v.unit)}"'
        body.append(f"    <!-- {pos} -->\n    <ScalarVariable {attrs}>\n      <{v.type}{inner}/>\n"
                    f"    </ScalarVariable>\n")
        if caus == "output":
            outputs.append(pos)
    body.append("  </ModelVariables>\n  <ModelStructure>\n    <Outputs>\n")
    body += [f'      <Unknown index="{i}"/>\n' for i in outputs]
    body.append("    </Outputs>\n    <InitialUnknowns>\n")
    body += [f'      <Unknown index="{i}"/>\n' for i in outputs]
    body.append("    </InitialUnknowns>\n  </ModelStructure>\n</fmiModelDescription>\n")
    return head + "".join(body)


def render_fmi3(spec: VariantSpec, token: str, *, default_stop: float = 60.0,
                default_step: float = 0.05) -> str:
    units = {v.unit for v in spec.variables if v.unit}
    now = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    tag = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean"}
    head = (f'<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<fmiModelDescription fmiVersion="3.0" modelName={quoteattr(spec.model_name)} '
            f'instantiationToken="{token}" description={quoteattr(spec.description)} '
            f'generationTool="calib.fmu.build" generationDateAndTime="{now}" '
            f'variableNamingConvention="structured">\n'
            f'  <CoSimulation modelIdentifier="{spec.model_identifier}" '
            f'canHandleVariableCommunicationStepSize="true" canGetAndSetFMUState="true" '
            f'canSerializeFMUState="true" providesIntermediateUpdate="false" hasEventMode="false"/>\n')
    body = [_unit_xml(units | {"s"}), _log_categories_xml(),
            f'  <DefaultExperiment startTime="0" stopTime="{default_stop:g}" stepSize="{default_step:g}"/>\n',
            "  <ModelVariables>\n",
            '    <Float64 name="time" valueReference="0" causality="independent" variability="continuous" '
            'unit="s" description="Simulation time"/>\n']
    outputs = []
    for v in spec.variables:
        caus, var = _causality(v)
        attrs = f'name={quoteattr(v.name)} valueReference="{v.vr}" causality="{caus}" variability="{var}"'
        if caus == "parameter":
            attrs += ' initial="exact"'
        if v.description:
            attrs += f" description={quoteattr(v.description)}"
        if v.start:
            attrs += ' start="' + " ".join(_fmt(s, v.type, True) for s in v.start) + '"'
        if v.min is not None:
            attrs += f' min="{_fmt(v.min, v.type, True)}" max="{_fmt(v.max, v.type, True)}"'
        if v.unit and v.type == "Real":
            attrs += f' unit="{escape(v.unit)}"'
        if v.array:
            body.append(f'    <{tag[v.type]} {attrs}>\n      <Dimension start="{v.count}"/>\n'
                        f'    </{tag[v.type]}>\n')
        else:
            body.append(f"    <{tag[v.type]} {attrs}/>\n")
        if caus == "output":
            outputs.append(v.vr)
    body.append("  </ModelVariables>\n  <ModelStructure>\n")
    body += [f'    <Output valueReference="{vr}"/>\n' for vr in outputs]
    body += [f'    <InitialUnknown valueReference="{vr}"/>\n' for vr in outputs]
    body.append("  </ModelStructure>\n</fmiModelDescription>\n")
    return head + "".join(body)


def render_c_table(spec: VariantSpec, token: str) -> str:
    """``fmu_variables.h``: the instantiation token and the sorted value-reference table."""
    kinds = {"input": "FK_INPUT", "tunable": "FK_TUNABLE", "fixed": "FK_FIXED", "output": "FK_OUTPUT"}
    types = {"Real": "FT_REAL", "Integer": "FT_INTEGER", "Boolean": "FT_BOOLEAN"}
    rows = []
    for v in sorted(spec.variables, key=lambda x: x.vr):
        start = float(v.start[0]) if v.start else 0.0
        if v.min is not None:
            lo, hi = v.min, v.max
        elif v.type == "Boolean":
            lo, hi = 0.0, 1.0
        else:                       # outputs: no range
            lo, hi = -1e308, 1e308
        rows.append(f'    {{{v.vr}u, CV_{v.core}, {v.index}, {v.count}, {types[v.type]}, {kinds[v.kind]}, '
                    f'{v.scale!r}, {v.offset!r}, {int(v.wrap360)}, {start!r}, {lo!r}, {hi!r}, '
                    f'"{v.name}", "{v.unit or ""}"}},')
    return ("/* fmu_variables.h -- GENERATED by calib/fmu/build.py from "
            f"fmu_models/.../variables.toml; do not edit. */\n"
            "#ifndef FMU_VARIABLES_H\n#define FMU_VARIABLES_H\n#include \"fmu_common.h\"\n"
            f'#define FMU_INSTANTIATION_TOKEN "{token}"\n'
            f"#define FMU_N_VARS {len(rows)}\n"
            "static const FmuVar FMU_VARS[FMU_N_VARS] = {\n" + "\n".join(rows) + "\n};\n#endif\n")


def render_build_description(spec: VariantSpec, sources: list[str]) -> str:
    """``sources/buildDescription.xml`` (read by fmpy's CMake build)."""
    files = "\n".join(f'      <SourceFile name="{s}"/>' for s in sources)
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<fmiBuildDescription fmiVersion="3.0">\n'
            f'  <BuildConfiguration modelIdentifier="{spec.model_identifier}">\n'
            '    <SourceFileSet language="C99">\n'
            f"{files}\n"
            "    </SourceFileSet>\n"
            "  </BuildConfiguration>\n"
            "</fmiBuildDescription>\n")
