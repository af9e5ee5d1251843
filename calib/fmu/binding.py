"""The mapping bound to the model description: checks and writes, without simulating.

Given a :class:`~calib.fmu.mapping.Mapping` and the FMU's variables
(:class:`~calib.fmu.variables.Variables`), this module checks every mapped variable (it exists; its
causality, variability and type fit its role; array elements lie inside their arrays; setting values
inside the FMU's range) and builds what a simulation writes: the fixed assignments of settings and
switches (:func:`fixed_assignments`), the calibrated parameters with their writers and unit
conversions (:func:`bind_parameters`) and the operating-condition inputs (:func:`bind_inputs`). What a
simulation reads, and the :class:`~calib.fmu.plan.SimulationPlan` that carries both, is made by
:func:`calib.fmu.signals.make_plan`; the channels are read by :func:`calib.fmu.channels.channel_specs`.
Nothing here runs the FMU.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.fmu import plan as fp
from calib.fmu.archive import FmuInputError
from calib.fmu.mapping import Mapping
from calib.fmu.mapping_entries import ParameterEntry
from calib.fmu.variables import Variables, type_class
from calib.types import CONDITION_DEFAULTS, CONDITION_FIELDS, Parameter

#: operating conditions an FMU without that input must see at this value: a table's defaults, and zero
#: pitch (an FMU without a pitch input runs with its blades at zero pitch)
IMPLICIT_CONDITIONS = {**CONDITION_DEFAULTS, "pitch": 0.0}


@dataclass(frozen=True)
class _Slot:
    """Where a package quantity sits in a flat vector of values written in one call."""

    vr: int
    size: int
    offset: int


class _Writer:
    """Builds one :class:`~calib.fmu.plan.Assignment` per FMI type for a set of
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


def _bits(x: float) -> bytes:
    """The 8 bytes of a double (-0.0 and 0.0 differ, as they may in the FMU's arithmetic)."""
    return struct.pack("<d", float(x))


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

    def canonical(self, assignments: tuple) -> tuple:
        """A key of the parameter values ``assignments`` (from :meth:`assignments`) that does not depend on
        which parameters a model calibrates: (value reference, element, FMU value) of each value off the
        FMU's start value, by value reference. Two models of one FMU calibrating different parameters write
        the same values when their keys are equal (a value at its start value is the FMU's own)."""
        if not assignments:
            return ()
        values = assignments[0].values
        off = [(s.vr, e, values[s.offset + e]) for s in self.writer.slots.values() for e in range(s.size)
               if _bits(values[s.offset + e]) != _bits(self.base[s.offset + e])]
        return tuple(sorted(off))


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
        if type_class(var) != "real":
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
        t = type_class(var)
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
        grid = _correction_grid(m, unzip_dir)
        index += _correction_indices(m, vs, w, grid)
        conv += [(m.corrections.scale, 0.0, 1)] * (2 * grid.n_lift)     # lift block, then drag block
        params += list(grid.parameters())
    for name in _selected_parameters(m, names):
        e = m.parameters[name]
        where = f"parameters.{name}"
        var = vs.get(e.variable, where)
        params.append(_scalar_parameter(name, e, var, vs, m.source, where))
        index.append(w.index(var, e.element, where))
        conv.append((e.scale, e.offset, e.sign))
    return ParameterBinding(tuple(params), grid, w, np.array(index, int), np.array(conv, float).reshape(-1, 3),
                            np.array(w.base, float))


def _correction_grid(m: Mapping, unzip_dir: str) -> CorrectionGrid:
    """The correction grid of ``[corrections]``: from its JSON file inside the FMU, or its own nodes.

    Parameters
    ----------
    m : Mapping
        A mapping with ``[corrections]``.
    unzip_dir : str
        The folder the FMU is extracted to (``grid`` names a file relative to it).

    Returns
    -------
    CorrectionGrid
        With the file's ``cl_scale``, ``cd_scale``, ``cl_bound``, ``cd_bound`` overridden by the mapping's.
    """
    c = m.corrections
    if c.grid_file:
        gpath = Path(unzip_dir) / c.grid_file
        if not gpath.is_file():
            raise FmuInputError(f"correction grid file {c.grid_file!r} is not in the FMU", m.source,
                                field="corrections.grid")
        info = json.loads(gpath.read_text())
        opts = {k: info[k] for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound") if k in info}
        return CorrectionGrid(info["alpha_nodes_deg"], info["eta_nodes"], **(opts | c.grid_options))
    return CorrectionGrid(c.alpha_nodes_deg, c.eta_nodes, **c.grid_options)


def _correction_indices(m: Mapping, vs: Variables, w: _Writer, grid: CorrectionGrid) -> list[int]:
    """Where each correction node is written: its position in ``w``'s flat vector, lift block then drag block.

    Parameters
    ----------
    m : Mapping
        A mapping with ``[corrections]`` (layout ``"array"``: one tunable array per block with one element
        per node; ``"scalar"``: one tunable scalar per node).
    vs : Variables
        The FMU's variables.
    w : _Writer
        The writer of the calibrated parameters (its slots are added here).
    grid : CorrectionGrid
        The correction grid (:func:`_correction_grid`).

    Returns
    -------
    list of int
        ``2 * grid.n_lift`` positions.
    """
    c = m.corrections
    index = []
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
    return index


def _selected_parameters(m: Mapping, names) -> list[str]:
    """The ``[parameters]`` names to calibrate: ``names`` (all when None), each one the mapping's."""
    selected = list(m.parameters) if names is None else list(names)
    unknown = [n for n in selected if n not in m.parameters]
    if unknown:
        raise InputError(f"unknown parameter(s) {', '.join(unknown)}; the mapping's [parameters]: "
                         f"{', '.join(m.parameters) or '(none)'}", m.source, field=f"parameters.{unknown[0]}")
    return selected


def _scalar_parameter(name: str, e: ParameterEntry, var, vs: Variables, source: str, where: str) -> Parameter:
    """The calibrated :class:`~calib.types.Parameter` of one ``[parameters]`` entry [package units].

    Parameters
    ----------
    name : str
        Its name in ``[parameters]``.
    e : ParameterEntry
        The entry: its nominal value and bounds (NaN: take the FMU's start value, min and max, converted).
    var : fmpy.model_description.ModelVariable
        The FMU variable it is written to.
    vs : Variables
        The FMU's variables (for the start value).
    source, where : str
        The mapping file and the entry's key, which errors name.

    Returns
    -------
    Parameter
        Nominal and bounds inside the FMU's range (converted to package units).
    """
    lo_f = float(var.min) if var.min is not None else -np.inf
    hi_f = float(var.max) if var.max is not None else np.inf
    fmu_range = np.sort(e.to_package(np.array([lo_f, hi_f])))
    start = vs.start_values(var, vs.size(var))[e.element or 0]
    nominal = float(e.to_package(start)) if np.isnan(e.nominal) else e.nominal
    lower = fmu_range[0] if np.isnan(e.lower) else e.lower
    upper = fmu_range[1] if np.isnan(e.upper) else e.upper
    if not (np.isfinite(lower) and np.isfinite(upper)):
        raise FmuInputError("no finite bounds: give 'lower' and 'upper' (the FMU declares no min/max)",
                            source, field=where)
    if lower < fmu_range[0] - 1e-12 * abs(fmu_range[0]) or upper > fmu_range[1] + 1e-12 * abs(fmu_range[1]):
        raise FmuInputError(f"bounds [{lower:g}, {upper:g}] exceed the FMU's range [{fmu_range[0]:g}, "
                            f"{fmu_range[1]:g}] (package units)", source, field=where)
    try:
        return Parameter(name, nominal, lower, upper, e.typical, e.package_unit or "-", e.kind,
                         description=e.description or f"FMU variable {e.variable}", prior_std=e.prior_std)
    except InputError as exc:
        raise FmuInputError(exc.message, source, field=where) from None


def bind_inputs(m: Mapping, vs: Variables) -> InputBinding:
    """The operating-condition inputs of ``[inputs]``: real variables, with their unit conversions."""
    w = _Writer(vs)
    fields, idx, conv = [], [], []
    for name, e in m.inputs.items():
        var = vs.get(e.variable, f"inputs.{name}")
        if type_class(var) != "real":
            raise FmuInputError(f"input {var.name!r} is {var.type}; operating conditions need real inputs",
                                m.source, field=f"inputs.{name}")
        idx.append(w.index(var, e.element, f"inputs.{name}"))
        conv.append((e.scale, e.offset, e.sign))
        fields.append(name)
    return InputBinding(tuple(fields), w, np.array(idx, int), np.array(conv, float).reshape(-1, 3),
                        np.array(w.base, float))
