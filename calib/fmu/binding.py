"""The mapping bound to the model description: checks and plans, without simulating.

Given a :class:`~calib.fmu.mapping.Mapping` and fmpy's model description (:class:`Variables`), this
module checks every mapped variable (it exists; its causality, variability and type fit its role;
array elements lie inside their arrays; setting values inside the FMU's range) and builds what a
simulation needs: the fixed assignments of settings and switches (:func:`fixed_assignments`), the
calibrated parameters with their writers and unit conversions (:func:`bind_parameters`), the
operating-condition inputs (:func:`bind_inputs`), the channels (read by
:func:`calib.fmu.channels.channel_specs`) and the
:class:`~calib.fmu.plan.SimulationPlan` (:func:`make_plan`). Nothing here runs the FMU: the radii of
spanwise stations, which only an initialized FMU knows, come in as a function.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.fmu import plan as fp
from calib.fmu.archive import FmuInputError
from calib.fmu.mapping import Mapping
from calib.types import CONDITION_DEFAULTS, CONDITION_FIELDS, Parameter

#: operating conditions an FMU without that input must see at this value: a table's defaults, and zero
#: pitch (an FMU without a pitch input runs with its blades at zero pitch)
IMPLICIT_CONDITIONS = {**CONDITION_DEFAULTS, "pitch": 0.0}


class Variables:
    """The model description's variables as a mapping uses them: lookup (with "did you mean"),
    causality and variability checks, array sizes, start values.

    Parameters
    ----------
    model_description : fmpy.model_description.ModelDescription
    fmu_name : str
        The FMU's file name, for messages.
    source : str
        The mapping file, which errors name.
    """

    def __init__(self, model_description, fmu_name: str, source: str):
        self.by_name = {v.name: v for v in model_description.modelVariables}
        self.fmu_name = fmu_name
        self.source = source

    def get(self, name: str, where: str):
        """The variable ``name`` (``where``: the mapping key that names it, for the error)."""
        v = self.by_name.get(name)
        if v is None:
            from difflib import get_close_matches
            close = get_close_matches(name, list(self.by_name), n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise FmuInputError(f"variable {name!r} does not exist in {self.fmu_name}{hint}",
                                self.source, field=where)
        return v

    def expect(self, var, where: str, causality: tuple, variability: tuple | None = None, what: str = ""):
        if var.causality not in causality:
            raise FmuInputError(f"variable {var.name!r} has causality {var.causality!r}; {what or 'expected'} "
                                f"{' or '.join(causality)}", self.source, field=where)
        if variability and var.variability not in variability:
            raise FmuInputError(f"variable {var.name!r} is not tunable (variability {var.variability!r}): it "
                                f"cannot change after initialization, so it cannot be calibrated (perturbed "
                                f"runs restart from a settled state); expected variability "
                                f"{' or '.join(variability)}", self.source, field=where)

    def size(self, var) -> int:
        n = 1
        for d in var.dimensions or []:
            if d.start is not None:
                n *= int(d.start)
            else:
                ref = d.variable if d.variable is not None else None
                n *= int(float(ref.start)) if ref is not None and ref.start is not None else 1
        return n

    def start_values(self, var, size: int) -> list:
        if var.start is None:
            return [0.0] * size
        vals = str(var.start).split()
        out = []
        for v in vals:
            out.append({"true": 1.0, "false": 0.0}.get(v.lower(), None) if v.lower() in ("true", "false")
                       else float(v))
        return (out * size)[:size] if len(out) == 1 else out[:size]


@dataclass(frozen=True)
class _Slot:
    """Where a package quantity sits in a flat vector of values written in one call."""

    vr: int
    size: int
    offset: int


class _Writer:
    """Builds one :class:`~calib.fmu.worker.Assignment` per FMI type for a set of
    variables, with array elements not mapped kept at their start values."""

    def __init__(self, variables: "Variables"):
        self.vars = variables
        self.slots: dict[str, _Slot] = {}
        self.base: list[float] = []

    def slot(self, var, where: str) -> _Slot:
        if var.name not in self.slots:
            size = self.vars.size(var)
            start = self.vars.start_values(var, size)
            self.slots[var.name] = _Slot(var.valueReference, size, len(self.base))
            self.base.extend(start)
        return self.slots[var.name]

    def index(self, var, element, where: str) -> int:
        s = self.slot(var, where)
        if element is None:
            if s.size != 1:
                raise FmuInputError(f"variable {var.name!r} is an array of {s.size}; give 'element'",
                                    self.vars.source, field=where)
            return s.offset
        if not 0 <= element < s.size:
            raise FmuInputError(f"element {element} is outside variable {var.name!r} ({s.size} elements)",
                                self.vars.source, field=where)
        return s.offset + element

    def assignment(self, flat: np.ndarray, type_: str) -> fp.Assignment:
        return fp.Assignment(type_, tuple(s.vr for s in self.slots.values()), tuple(np.asarray(flat).tolist()))


def _type_class(var) -> str:
    if var.type in fp.REAL_TYPES:
        return "real"
    if var.type in fp.INTEGER_TYPES:
        return "integer"
    if var.type in fp.BOOLEAN_TYPES:
        return "boolean"
    return var.type




@dataclass(frozen=True)
class ParameterBinding:
    """The calibrated parameters and how a parameter vector becomes FMU assignments."""

    parameters: tuple
    grid: CorrectionGrid | None
    writer: "_Writer"
    index: np.ndarray       # position of each parameter in the writer's flat vector
    conv: np.ndarray        # (n, 3): scale, offset, sign of each parameter's conversion to FMU units
    base: np.ndarray        # the flat vector's start values (array elements not calibrated)

    def assignments(self, p: np.ndarray) -> tuple:
        """FMU-side values of ``p`` (package units): one real assignment, or none without parameters."""
        flat = self.base.copy()
        if p.size:
            c = self.conv
            flat[self.index] = (c[:, 2] * p - c[:, 1]) / c[:, 0]
        return (self.writer.assignment(flat, "real"),) if self.writer.slots else ()


@dataclass(frozen=True)
class InputBinding:
    """The operating-condition inputs and how conditions become FMU assignments."""

    fields: tuple           # condition field per input, in the mapping's order
    writer: "_Writer"
    index: np.ndarray
    conv: np.ndarray        # (n, 3): scale, offset, sign
    base: np.ndarray

    def assignments(self, m: Mapping, conditions) -> list[tuple]:
        """One assignment per operating point; a condition the mapping has no input for must be at its
        default (else :class:`~calib.errors.InputError` naming it)."""
        for name in CONDITION_FIELDS:
            if name in m.inputs:
                continue
            values = getattr(conditions, name)
            default = IMPLICIT_CONDITIONS.get(name)
            if default is None or np.any(values != default):
                raise InputError(f"the operating conditions set {name} (e.g. {values[values != default][0]:g}) but "
                                 f"the mapping maps no input for it; add inputs.{name} or drop it from the data",
                                 m.source, field=f"inputs.{name}")
        cols = np.column_stack([getattr(conditions, f) for f in self.fields])
        c = self.conv
        fmu = (c[:, 2] * cols - c[:, 1]) / c[:, 0]
        out = []
        for row in fmu:
            flat = self.base.copy()
            flat[self.index] = row
            out.append((self.writer.assignment(flat, "real"),))
        return out


@dataclass(frozen=True)
class PlanSite:
    """What a plan needs of the FMU beyond the mapping: identity, extraction folder, fixed assignments,
    steady windows and state capabilities."""

    fmi_version: str
    model_identifier: str
    guid: str
    unzip_dir: str
    sha256: str
    fixed: tuple
    steady: object
    can_get_state: bool
    can_serialize: bool


def check_mapped_variables(m: Mapping, vs: Variables) -> None:
    """Every variable the mapping names exists with a causality (and variability, type) fit for its role."""
    for name, e in m.inputs.items():
        vs.expect(vs.get(e.variable, f"inputs.{name}"), f"inputs.{name}", ("input", "parameter"))
    for name, e in m.outputs.items():
        vs.expect(vs.get(e.variable, f"outputs.{name}"), f"outputs.{name}", ("output", "local"))
    for name, sp in m.spanwise.items():
        for v in (*sp.variables, *([sp.variable] if sp.variable else []), *sp.radius_variables,
                  *([sp.radius_variable] if sp.radius_variable else [])):
            vs.expect(vs.get(v, f"outputs.{name}"), f"outputs.{name}", ("output", "local"))
    for name, e in m.parameters.items():
        var = vs.get(e.variable, f"parameters.{name}")
        vs.expect(var, f"parameters.{name}", ("parameter", "input"), ("tunable", "continuous", "discrete"))
        if _type_class(var) != "real":
            raise FmuInputError(f"variable {var.name!r} is {var.type}; calibrated parameters must be real",
                                m.source, field=f"parameters.{name}")
    for name, e in m.settings.items():
        vs.expect(vs.get(e.variable, f"settings.{name}"), f"settings.{name}", ("parameter",))
    for name, s in m.switches.items():
        vs.expect(vs.get(s.variable, f"switches.{name}"), f"switches.{name}", ("parameter",))
    if m.rotor_radius is not None and not isinstance(m.rotor_radius, float):
        vs.expect(vs.get(m.rotor_radius.variable, "rotor.radius"), "rotor.radius",
                     ("output", "local", "parameter", "calculatedParameter"))


def fixed_assignments(m: Mapping, vs: Variables, switches: dict, settings: dict) -> tuple:
    """The assignments of the settings and switches (mapping defaults, overridden by ``settings`` and
    ``switches`` in package units), one per FMI type, checked against the FMU's ranges."""
    groups: dict[str, _Writer] = {}
    values: dict[str, dict[int, float]] = {}

    def put(var, element, value, where):
        t = _type_class(var)
        if t not in ("real", "integer", "boolean"):
            raise FmuInputError(f"variable {var.name!r} has unsupported type {var.type}", m.source, field=where)
        w = groups.setdefault(t, _Writer(vs))
        i = w.index(var, element, where)
        lo = float(var.min) if var.min is not None else -np.inf
        hi = float(var.max) if var.max is not None else np.inf
        v = float(value)
        if not (lo <= v <= hi):
            raise FmuInputError(f"value {value!r} (FMU units) for {var.name!r} is outside its range [{lo:g}, "
                                f"{hi:g}]", m.source, field=where)
        values.setdefault(t, {})[i] = v

    unknown = [k for k in settings if k not in m.settings]
    if unknown:
        raise InputError(f"unknown setting(s) {', '.join(unknown)}; the mapping's [settings]: "
                         f"{', '.join(m.settings) or '(none)'}", m.source, field=f"settings.{unknown[0]}")
    for name, e in m.settings.items():
        value = settings.get(name, e.value)
        if value is None:
            continue
        var = vs.get(e.variable, f"settings.{name}")
        put(var, e.element, float(e.to_fmu(float(value))), f"settings.{name}")
    unknown = [k for k in switches if k not in m.switches]
    if unknown:
        raise InputError(f"unknown switch(es) {', '.join(unknown)}; the mapping's [switches]: "
                         f"{', '.join(m.switches) or '(none)'}", m.source, field=f"switches.{unknown[0]}")
    for name, setting in switches.items():
        s = m.switches[name]
        var = vs.get(s.variable, f"switches.{name}")
        put(var, None, float(s.value(setting, m.source)), f"switches.{name}")
    out = []
    for t, w in groups.items():
        flat = np.array(w.base, float)
        for i, v in values.get(t, {}).items():
            flat[i] = v
        out.append(w.assignment(flat, t))
    return tuple(out)


def bind_parameters(m: Mapping, vs: Variables, names, corrections: bool, unzip_dir: str) -> ParameterBinding:
    """The calibrated parameters: the correction nodes of ``[corrections]`` (when ``corrections``) then the
    mapping's ``[parameters]`` (``names``, default all), with where and how each is written."""
    w = _Writer(vs)
    params, index, conv = [], [], []   # conv: (scale, offset, sign) package -> fmu
    grid = None
    if corrections and m.corrections is not None:
        c = m.corrections
        if c.grid_file:
            gpath = Path(unzip_dir) / c.grid_file
            if not gpath.is_file():
                raise FmuInputError(f"correction grid file {c.grid_file!r} is not in the FMU", m.source,
                                    field="corrections.grid")
            info = json.loads(gpath.read_text())
            opts = {k: info[k] for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound") if k in info}
            grid = CorrectionGrid(info["alpha_nodes_deg"], info["eta_nodes"], **(opts | c.grid_options))
        else:
            grid = CorrectionGrid(c.alpha_nodes_deg, c.eta_nodes, **c.grid_options)
        lift, drag = c.variable_names(grid.n_alpha, grid.n_eta)
        for block, vnames in (("lift", lift), ("drag", drag)):
            where = f"corrections.{block}"
            if c.layout == "array":
                var = vs.get(vnames[0], where)
                vs.expect(var, where, ("parameter",), ("tunable",))
                if vs.size(var) != grid.n_lift:
                    raise FmuInputError(f"array {var.name!r} has {vs.size(var)} elements, the correction grid "
                                        f"{grid.n_lift} nodes", m.source, field=where)
                index += [w.index(var, k, where) for k in range(grid.n_lift)]
            else:
                for vn in vnames:
                    var = vs.get(vn, where)
                    vs.expect(var, where, ("parameter",), ("tunable",))
                    index.append(w.index(var, None, where))
            conv += [(c.scale, 0.0, 1)] * grid.n_lift
        params += list(grid.parameters())
    selected = list(m.parameters) if names is None else list(names)
    unknown = [n for n in selected if n not in m.parameters]
    if unknown:
        raise InputError(f"unknown parameter(s) {', '.join(unknown)}; the mapping's [parameters]: "
                         f"{', '.join(m.parameters) or '(none)'}", m.source, field=f"parameters.{unknown[0]}")
    for name in selected:
        e = m.parameters[name]
        where = f"parameters.{name}"
        var = vs.get(e.variable, where)
        lo_f = float(var.min) if var.min is not None else -np.inf
        hi_f = float(var.max) if var.max is not None else np.inf
        fmu_range = np.sort(e.to_package(np.array([lo_f, hi_f])))
        start = vs.start_values(var, vs.size(var))[e.element or 0]
        nominal = float(e.to_package(start)) if np.isnan(e.nominal) else e.nominal
        lower = fmu_range[0] if np.isnan(e.lower) else e.lower
        upper = fmu_range[1] if np.isnan(e.upper) else e.upper
        if not (np.isfinite(lower) and np.isfinite(upper)):
            raise FmuInputError("no finite bounds: give 'lower' and 'upper' (the FMU declares no min/max)",
                                m.source, field=where)
        if lower < fmu_range[0] - 1e-12 * abs(fmu_range[0]) or upper > fmu_range[1] + 1e-12 * abs(fmu_range[1]):
            raise FmuInputError(f"bounds [{lower:g}, {upper:g}] exceed the FMU's range [{fmu_range[0]:g}, "
                                f"{fmu_range[1]:g}] (package units)", m.source, field=where)
        try:
            params.append(Parameter(name, nominal, lower, upper, e.typical, e.package_unit or "-", e.kind,
                                    description=e.description or f"FMU variable {e.variable}",
                                    prior_std=e.prior_std))
        except InputError as exc:
            raise FmuInputError(exc.message, m.source, field=where) from None
        index.append(w.index(var, e.element, where))
        conv.append((e.scale, e.offset, e.sign))
    return ParameterBinding(tuple(params), grid, w, np.array(index, int), np.array(conv, float).reshape(-1, 3),
                            np.array(w.base, float))


def bind_inputs(m: Mapping, vs: Variables) -> InputBinding:
    """The operating-condition inputs of ``[inputs]``: real variables, with their unit conversions."""
    w = _Writer(vs)
    fields, idx, conv = [], [], []
    for name, e in m.inputs.items():
        var = vs.get(e.variable, f"inputs.{name}")
        if _type_class(var) != "real":
            raise FmuInputError(f"input {var.name!r} is {var.type}; operating conditions need real inputs",
                                m.source, field=f"inputs.{name}")
        idx.append(w.index(var, e.element, f"inputs.{name}"))
        conv.append((e.scale, e.offset, e.sign))
        fields.append(name)
    return InputBinding(tuple(fields), w, np.array(idx, int), np.array(conv, float).reshape(-1, 3),
                        np.array(w.base, float))


def make_plan(m: Mapping, vs: Variables, site: PlanSite, specs: list, grid, signals_only: bool = False) -> tuple:
    """The :class:`~calib.fmu.plan.SimulationPlan` of these channels (``specs``, :func:`channel_specs`) and the
    index of each signal key in its values; ``signals_only``: the azimuth alone (to probe radii)."""
    reads: dict[str, tuple[int, int, int]] = {}     # variable -> (vr, size, offset)
    count = 0

    def flat(var_name: str, element) -> int:
        nonlocal count
        if var_name not in reads:
            var = vs.by_name[var_name]
            size = vs.size(var)
            reads[var_name] = (var.valueReference, size, count)
            count += size
        vr, size, off = reads[var_name]
        return off + (element or 0)

    signals, keys = [], {}
    checked = []

    def add(key, var_name, element, scale=1.0, offset=0.0, sign=1, wrap=None, check=False, name=None):
        if key in keys:
            if check and keys[key] not in checked:
                checked.append(keys[key])
            return keys[key]
        keys[key] = len(signals)
        signals.append(fp.Signal(name or str(key), flat(var_name, element), scale, offset, sign, wrap))
        if check:
            checked.append(keys[key])
        return keys[key]

    if not signals_only:
        for _, key, _, _, _ in specs:
            if key[0] == "out":
                e = m.outputs[key[1]]
                var = vs.by_name[e.variable]
                if _type_class(var) != "real":
                    raise FmuInputError(f"output {var.name!r} is {var.type}; channels need real outputs", m.source,
                                        field=f"outputs.{key[1]}")
                add(key, e.variable, e.element, e.scale, e.offset, e.sign, e.wrap, True, key[1])
            else:
                sp = m.spanwise[key[1]]
                vname = sp.variables[key[2]] if sp.variables else sp.variable
                elem = None if sp.variables else key[2]
                add(key, vname, elem, sp.scale, sp.offset, 1, None, True, f"{key[1]}[{key[2]}]")
        if "angle_of_attack" in m.spanwise and grid is not None:
            sp = m.spanwise["angle_of_attack"]
            n = len(sp.variables) if sp.variables else vs.size(vs.by_name[sp.variable])
            for k in range(n):
                vname = sp.variables[k] if sp.variables else sp.variable
                add(("span", "angle_of_attack", k), vname, None if sp.variables else k, sp.scale, sp.offset,
                    1, None, False, f"angle_of_attack[{k}]")
    azimuth = None
    if m.azimuth is not None:
        e = m.azimuth
        azimuth = add(("out", "azimuth"), e.variable, e.element, e.scale, e.offset, e.sign, e.wrap or 360.0,
                      False, "azimuth")
    counters = []
    if "aero_failures" in m.outputs and not signals_only:
        e = m.outputs["aero_failures"]
        var = vs.by_name[e.variable]
        counters.append(fp.Counter("aero_failures", var.valueReference, _type_class(var)))
    plan = fp.SimulationPlan(
        key="", fmi_version=site.fmi_version, model_identifier=site.model_identifier, guid=site.guid,
        unzip_dir=site.unzip_dir, fixed=site.fixed, read_vrs=tuple(v[0] for v in reads.values()),
        read_count=count, signals=tuple(signals), azimuth=azimuth, checked=tuple(checked),
        counters=tuple(counters), steady=site.steady, can_get_state=site.can_get_state,
        can_serialize=site.can_serialize)
    digest = hashlib.sha256(site.sha256.encode() + repr(plan).encode()).hexdigest()[:20]
    return fp.SimulationPlan(**{**plan.__dict__, "key": digest}), dict(keys)

