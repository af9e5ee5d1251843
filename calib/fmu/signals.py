"""What a simulation reads: the signals of the channels and the plan that carries them.

:func:`make_plan` turns the channels of an FMU model (:func:`calib.fmu.channels.channel_specs`) into
the :class:`~calib.fmu.plan.SimulationPlan` a worker runs: the variables read at every step (one
flat vector of values), the :class:`~calib.fmu.plan.Signal` each channel's output or spanwise
station gives (with its conversion to package units), the angles of attack at the stations (for the
correction field), the azimuth, and the counters; the rest of the plan (identity, extraction folder,
fixed assignments, steady windows, state capabilities) comes in as a :class:`PlanSite`. Nothing
here runs the FMU.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

from calib.fmu import plan as fp
from calib.fmu.archive import FmuInputError
from calib.fmu.mapping import Mapping
from calib.fmu.variables import Variables, type_class


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


class _SignalTable:
    """The signals of a plan being made and the variables they read.

    Parameters
    ----------
    variables : Variables
        The FMU's variables.

    Attributes
    ----------
    reads : dict
        Variable name -> (value reference, size, offset in the flat vector of values read).
    count : int
        Length of that flat vector.
    signals : list of Signal
        In the order they were added.
    keys : dict
        Signal key -> its index in ``signals``.
    checked : list of int
        Indices of the signals whose window halves the convergence check compares.
    """

    def __init__(self, variables: Variables):
        self.vs = variables
        self.reads: dict[str, tuple[int, int, int]] = {}     # variable -> (vr, size, offset)
        self.count = 0
        self.signals: list = []
        self.keys: dict = {}
        self.checked: list = []

    def flat(self, var_name: str, element) -> int:
        """Position of ``var_name`` (``element`` of an array) in the flat vector of values read."""
        if var_name not in self.reads:
            var = self.vs.by_name[var_name]
            size = self.vs.size(var)
            self.reads[var_name] = (var.valueReference, size, self.count)
            self.count += size
        vr, size, off = self.reads[var_name]
        return off + (element or 0)

    def add(self, key, var_name, element, scale=1.0, offset=0.0, sign=1, wrap=None, check=False, name=None) -> int:
        """The index of the signal ``key``, added (reading ``var_name``) unless it is there already.

        ``scale``, ``offset``, ``sign``, ``wrap``: its conversion to package units; ``check``: the
        convergence check compares its window halves; ``name``: its name (default ``str(key)``).
        """
        keys, checked = self.keys, self.checked
        if key in keys:
            if check and keys[key] not in checked:
                checked.append(keys[key])
            return keys[key]
        keys[key] = len(self.signals)
        self.signals.append(fp.Signal(name or str(key), self.flat(var_name, element), scale, offset, sign, wrap))
        if check:
            checked.append(keys[key])
        return keys[key]


def _add_channel_signals(table: _SignalTable, m: Mapping, vs: Variables, specs: list) -> None:
    """The signal of every channel: a mapped output (real ones only) or a spanwise station."""
    for _, key, _, _, _ in specs:
        if key[0] == "out":
            e = m.outputs[key[1]]
            var = vs.by_name[e.variable]
            if type_class(var) != "real":
                raise FmuInputError(f"output {var.name!r} is {var.type}; channels need real outputs", m.source,
                                    field=f"outputs.{key[1]}")
            table.add(key, e.variable, e.element, e.scale, e.offset, e.sign, e.wrap, True, key[1])
        else:
            sp = m.spanwise[key[1]]
            vname = sp.variables[key[2]] if sp.variables else sp.variable
            elem = None if sp.variables else key[2]
            table.add(key, vname, elem, sp.scale, sp.offset, 1, None, True, f"{key[1]}[{key[2]}]")


def _add_angle_of_attack(table: _SignalTable, m: Mapping, vs: Variables) -> None:
    """The angle of attack at every output station (not checked for convergence), for the correction field."""
    sp = m.spanwise["angle_of_attack"]
    n = len(sp.variables) if sp.variables else vs.size(vs.by_name[sp.variable])
    for k in range(n):
        vname = sp.variables[k] if sp.variables else sp.variable
        table.add(("span", "angle_of_attack", k), vname, None if sp.variables else k, sp.scale, sp.offset,
                  1, None, False, f"angle_of_attack[{k}]")


def _counters(m: Mapping, vs: Variables) -> tuple:
    """The counters a run reads at its end: the FMU's aerodynamic failures, when mapped."""
    counters = []
    if "aero_failures" in m.outputs:
        e = m.outputs["aero_failures"]
        var = vs.by_name[e.variable]
        counters.append(fp.Counter("aero_failures", var.valueReference, type_class(var)))
    return tuple(counters)


def _keyed_plan(site: PlanSite, table: _SignalTable, azimuth, counters: tuple) -> fp.SimulationPlan:
    """The plan of ``table``'s signals at ``site``, keyed by a digest of the FMU's SHA-256 and the plan."""
    plan = fp.SimulationPlan(
        key="", fmi_version=site.fmi_version, model_identifier=site.model_identifier, guid=site.guid,
        unzip_dir=site.unzip_dir, fixed=site.fixed, read_vrs=tuple(v[0] for v in table.reads.values()),
        read_count=table.count, signals=tuple(table.signals), azimuth=azimuth, checked=tuple(table.checked),
        counters=counters, steady=site.steady, can_get_state=site.can_get_state,
        can_serialize=site.can_serialize)
    digest = hashlib.sha256(site.sha256.encode() + repr(plan).encode()).hexdigest()[:20]
    return fp.SimulationPlan(**{**plan.__dict__, "key": digest})


def make_plan(m: Mapping, vs: Variables, site: PlanSite, specs: list, grid, signals_only: bool = False) -> tuple:
    """The :class:`~calib.fmu.plan.SimulationPlan` of these channels and the index of each signal key in its values.

    Parameters
    ----------
    m : Mapping
        The mapping.
    vs : Variables
        The FMU's variables (the mapped ones checked by :func:`calib.fmu.binding.check_mapped_variables`).
    site : PlanSite
        The rest of the plan: identity, extraction folder, fixed assignments, steady windows.
    specs : list of tuple
        The channels (:func:`calib.fmu.channels.channel_specs`).
    grid : CorrectionGrid or None
        The calibrated correction grid: with one, the angles of attack at the stations are read too.
    signals_only : bool
        The azimuth alone, no channels and no counters (to probe radii).

    Returns
    -------
    plan : SimulationPlan
        Keyed by a digest of the FMU's SHA-256 and the plan.
    keys : dict
        Signal key (``("out", name)``, ``("span", name, station)``) -> index in ``plan.signals``.
    """
    table = _SignalTable(vs)
    if not signals_only:
        _add_channel_signals(table, m, vs, specs)
        if "angle_of_attack" in m.spanwise and grid is not None:
            _add_angle_of_attack(table, m, vs)
    azimuth = None
    if m.azimuth is not None:
        e = m.azimuth
        azimuth = table.add(("out", "azimuth"), e.variable, e.element, e.scale, e.offset, e.sign, e.wrap or 360.0,
                            False, "azimuth")
    counters = () if signals_only else _counters(m, vs)
    return _keyed_plan(site, table, azimuth, counters), dict(table.keys)
