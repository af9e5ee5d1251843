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
                if type_class(var) != "real":
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
        counters.append(fp.Counter("aero_failures", var.valueReference, type_class(var)))
    plan = fp.SimulationPlan(
        key="", fmi_version=site.fmi_version, model_identifier=site.model_identifier, guid=site.guid,
        unzip_dir=site.unzip_dir, fixed=site.fixed, read_vrs=tuple(v[0] for v in reads.values()),
        read_count=count, signals=tuple(signals), azimuth=azimuth, checked=tuple(checked),
        counters=tuple(counters), steady=site.steady, can_get_state=site.can_get_state,
        can_serialize=site.can_serialize)
    digest = hashlib.sha256(site.sha256.encode() + repr(plan).encode()).hexdigest()[:20]
    return fp.SimulationPlan(**{**plan.__dict__, "key": digest}), dict(keys)
