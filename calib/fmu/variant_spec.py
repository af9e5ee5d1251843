"""Variable specs of the FMU variants: ``variables.toml`` read, checked and expanded.

Each variant declares its variables in ``fmu_models/<variant>/variables.toml`` (schema in
``fmu_models/README.md``). :func:`load_spec` checks that declaration and expands it for one rotor
and correction grid (one scalar per node or one array, one variable per blade or an array,
...) into :class:`FmuVariable` s with value references: a :class:`VariantSpec`, which
:mod:`calib.fmu.model_description` renders. The units a spec may name are those of
:data:`UNITS`.

The core variable ids (``CV_*``) are parsed from ``fmu_models/core/rotor_core.h`` so a
spec that names an unknown core variable fails here, at build time, with its name.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from calib.errors import InputError, unknown_key

KINDS = ("input", "tunable", "fixed", "output")
TYPES = ("Real", "Integer", "Boolean")
EXPANSIONS = ("nodes", "blades", "out_stations")
MAX_BLADES = 3

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
