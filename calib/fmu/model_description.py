"""Expanded variable specs of the FMU variants -> ``modelDescription.xml`` and the C value-reference table.

A :class:`~calib.fmu.variant_spec.VariantSpec` (read and expanded by
:func:`calib.fmu.variant_spec.load_spec`) is rendered here as

- ``modelDescription.xml`` (FMI 2.0 by :func:`render_fmi2`, 3.0 by :func:`render_fmi3`),
- ``fmu_variables.h`` (:func:`render_c_table`), the table the C wrappers use to map value
  references to core variables with the unit map ``fmu = scale * core + offset``, and
- ``sources/buildDescription.xml`` (:func:`render_build_description`).
"""

from __future__ import annotations

from datetime import datetime, timezone
from xml.sax.saxutils import escape, quoteattr

from calib.fmu.variant_spec import UNITS, FmuVariable, VariantSpec

#: Log categories of both FMUs (the same names, in this order, as LOG_CATEGORY in
#: fmu_models/core/fmu_slave.c): written into ``<LogCategories>`` of the model descriptions.
LOG_CATEGORIES = (
    ("logEvents", "Life-cycle events (initialization); off unless logging is on"),
    ("logStatusWarning", "Warnings"),
    ("logStatusError", "Refused calls and failures: the variable and its range, the time, the state"),
)


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
