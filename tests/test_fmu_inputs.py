"""The rotor FMUs refuse what they cannot simulate: absurd inputs and parameters (ranges
``min``/``max`` of ``variables.toml``, also in the model description), partial array sets,
steps that do not continue from the FMU's time, and steps needing too many sub-steps.

Every refusal must come with an error status (fmpy raises ``FMICallException``) and a log
message naming the variable (or the time) and leave the instance as it was.

:class:`Fmu` is a small raw-FMI driver (plain fmpy) used by the other ``test_fmu_*`` files too.
"""

from __future__ import annotations

import re
import tomllib
import numpy as np
import pytest

import fmpy  # noqa: E402  (a core dependency: a missing install must fail, not skip)
from fmpy.fmi1 import FMICallException

from calib.fmu.build import variant_dir


class Fmu:
    """One co-simulation instance of variant A (FMI 2) or B (FMI 3), driven by name.

    Log messages are collected in ``messages`` (status, category, text).
    """

    def __init__(self, path, variant: str):
        self.variant = variant
        self.md = fmpy.read_model_description(str(path))
        self.vars = {v.name: v for v in self.md.modelVariables}
        self.unzip = fmpy.extract(str(path))
        self.messages: list[tuple[int, str, str]] = []
        mi = self.md.coSimulation.modelIdentifier
        if variant == "A":
            from fmpy.fmi2 import (FMU2Slave, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
            from fmpy.fmi1 import calloc, free

            # no fmpy logger proxy (one global in fmpy): these FMUs pass the whole message as
            # the format, '%' doubled, without variadic arguments
            def logger(env, name, status, category, message):
                self.messages.append((status, category.decode(), message.decode().replace("%%", "%")))

            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(logger)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self._keep = (cb, logger)
            self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzip, modelIdentifier=mi)
            self.slave.instantiate(callbacks=cb)
        else:
            from fmpy.fmi3 import FMU3Slave

            def logger(env, status, category, message):
                self.messages.append((status, category.decode(), message.decode()))

            self._keep = (logger,)
            self.slave = FMU3Slave(guid=self.md.instantiationToken, unzipDirectory=self.unzip, modelIdentifier=mi)
            self.slave.instantiate(logMessage=logger)
        self.time = 0.0

    # -- life cycle -------------------------------------------------------
    def initialize(self, start_time: float = 0.0):
        if self.variant == "A":
            self.slave.setupExperiment(startTime=start_time)
            self.slave.enterInitializationMode()
        else:
            self.slave.enterInitializationMode(startTime=start_time)
        self.slave.exitInitializationMode()
        self.time = start_time
        return self

    def step(self, h: float, current: float | None = None):
        t = self.time if current is None else current
        self.slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        self.time = t + h

    def close(self):
        self.slave.terminate()
        self.slave.freeInstance()

    # -- values -------------------------------------------------------------
    def _kind(self, name):
        return self.vars[name].type  # Real/Integer/Boolean (FMI 2), Float64/Int32/Boolean (FMI 3)

    def size(self, name) -> int:
        dims = self.vars[name].dimensions
        return int(dims[0].start) if dims else 1

    def get(self, name):
        v, kind = self.vars[name], self._kind(name)
        if self.variant == "A":
            fn = {"Real": self.slave.getReal, "Integer": self.slave.getInteger,
                  "Boolean": self.slave.getBoolean}[kind]
            return fn([v.valueReference])[0]
        fn = {"Float64": self.slave.getFloat64, "Int32": self.slave.getInt32,
              "Boolean": self.slave.getBoolean}[kind]
        values = fn([v.valueReference], nValues=self.size(name))
        return values if v.dimensions else values[0]

    def set(self, **values):
        """Set several variables in ONE FMI call per type (all scalars of A, arrays of B)."""
        by_kind: dict[str, tuple[list, list]] = {}
        for name, value in values.items():
            v = self.vars[name]
            refs, vals = by_kind.setdefault(self._kind(name), ([], []))
            refs.append(v.valueReference)
            items = np.atleast_1d(value).tolist()
            if self._kind(name) in ("Integer", "Int32"):
                items = [int(x) for x in items]
            vals.extend(items)
        for kind, (refs, vals) in by_kind.items():
            if self.variant == "A":
                {"Real": self.slave.setReal, "Integer": self.slave.setInteger,
                 "Boolean": self.slave.setBoolean}[kind](refs, vals)
            else:
                {"Float64": self.slave.setFloat64, "Int32": self.slave.setInt32,
                 "Boolean": self.slave.setBoolean}[kind](refs, vals)

    def errors(self) -> str:
        return "\n".join(m for s, _, m in self.messages if s >= 3)


# the same physical quantity under each vendor's name and unit
NAMES = {
    "A": dict(wind="wind_speed", rotor_speed="rotor_speed", rpm=1.0, power="power", tilt="shaft_tilt",
              pitch_offset="pitch_offset_blade1", dcd="dCD_a2_e2", density="air_density",
              dcl="dCL_a0_e0", blades="number_of_blades", damping="flap_damping_ratio"),
    "B": dict(wind="Wind.Vhub", rotor_speed="Rotor.Omega", rpm=np.pi / 30, power="Rotor.Power",
              tilt="Rotor.ShaftTilt", pitch_offset="Control.PitchOffset", dcd="Aero.Polar.DeltaCD",
              density="Env.Rho", dcl="Aero.Polar.DeltaCL", blades="Rotor.NumBlades",
              damping="Struct.FlapDamping"),
}


@pytest.fixture
def open_fmu(fmus):
    opened = []

    def make(variant):
        f = Fmu(fmus[variant], variant)
        opened.append(f)
        return f
    yield make
    for f in opened:
        f.slave.freeInstance()


# ------------------------------------------------------------------ ranges
@pytest.mark.parametrize("variant", ["A", "B"])
def test_model_description_carries_the_ranges_of_variables_toml(fmus, variant):
    """Every input and every Real/Integer parameter has min and max in the model description,
    equal to the range declared in variables.toml, with min <= start <= max."""
    with open(variant_dir(variant) / "variables.toml", "rb") as fh:
        declared = {v["name"]: v for v in tomllib.load(fh)["variable"]}
    md = fmpy.read_model_description(str(fmus[variant]))
    checked = 0
    for v in md.modelVariables:
        if v.causality not in ("input", "parameter") or v.type == "Boolean":
            continue
        assert v.min is not None and v.max is not None, f"{v.name} has no range"
        lo, hi = float(v.min), float(v.max)
        assert lo <= hi
        for s in str(v.start).split():
            assert lo <= float(s) <= hi, v.name
        spec = next(d for n, d in declared.items()
                    if re.fullmatch(re.sub(r"\\\{\w+\\\}", ".+", re.escape(n)), v.name))
        assert (lo, hi) == (float(spec["min"]), float(spec["max"])), v.name
        checked += 1
    assert checked > 20
    rs = next(v for v in md.modelVariables if v.name == NAMES[variant]["rotor_speed"])
    assert float(rs.min) == 0.0


ABSURD = [  # quantity, value in package units (rotor speed rpm), when
    ("rotor_speed", -9.0, "step"),      # -1.34 MW before
    ("dcd", -5.0, "step"),              # 18.9 MW at 8 m/s before
    ("pitch_offset", 1e6, "step"),
    ("tilt", 90.0, "instantiated"),
    ("wind", -1.0, "instantiated"),
    ("density", float("nan"), "step"),
    ("blades", 1000, "instantiated"),
]


@pytest.mark.parametrize("variant", ["A", "B"])
@pytest.mark.parametrize("quantity,value,when", ABSURD)
def test_absurd_value_refused_with_message_and_nothing_changed(open_fmu, variant, quantity, value, when):
    names = NAMES[variant]
    name = names[quantity]
    f = open_fmu(variant)
    if when == "step":
        f.initialize()
        f.step(0.05)
    if quantity == "rotor_speed":
        value = value * names["rpm"]
    before = np.array(f.get(name), float)
    new = np.full(f.size(name), value) if f.size(name) > 1 else value
    with pytest.raises(FMICallException):
        f.set(**{name: new})
    assert name in f.errors() and "outside its range" in f.errors(), f.errors()
    assert np.array_equal(np.array(f.get(name), float), before)
    if when == "step":  # the instance goes on as if nothing happened
        f.step(0.05)
        assert np.isfinite(f.get(names["power"]))


@pytest.mark.parametrize("variant", ["A", "B"])
def test_refused_set_is_atomic(open_fmu, variant):
    """A call that sets several variables (FMI 2) or an array (FMI 3) with one bad value
    writes none of them: validate everything, then write."""
    names = NAMES[variant]
    f = open_fmu(variant)
    f.initialize()
    if variant == "A":
        with pytest.raises(FMICallException):
            f.set(**{names["dcl"]: 0.3, "dCL_a1_e0": 0.2, names["dcd"]: -5.0})
        assert f.get(names["dcl"]) == 0.0 and f.get("dCL_a1_e0") == 0.0
    else:
        n = f.size(names["dcd"])
        bad = np.full(n, 0.01)
        bad[n - 1] = -5.0                      # only the last element is out of range
        with pytest.raises(FMICallException):
            f.set(**{names["dcd"]: bad})
        assert np.all(np.array(f.get(names["dcd"])) == 0.0)
        with pytest.raises(FMICallException):  # several arrays in one call, the second bad
            f.set(**{names["dcl"]: np.full(n, 0.2), names["dcd"]: bad})
        assert np.all(np.array(f.get(names["dcl"])) == 0.0)
    assert "outside its range" in f.errors()


@pytest.mark.parametrize("variant", ["A", "B"])
def test_standstill_and_zero_wind_are_simulated(open_fmu, variant):
    """Wind 0 and rotor speed 0 are inside the ranges: finite outputs, no error (the polar
    lookup must not convert a NaN angle to int)."""
    names = NAMES[variant]
    for wind, rpm in ((0.0, 9.0), (0.0, 0.0), (8.0, 0.0)):
        f = open_fmu(variant)
        f.set(**{names["wind"]: wind})
        f.set(**{names["rotor_speed"]: rpm * names["rpm"]})
        f.initialize()
        for _ in range(4):
            f.step(0.05)
        assert np.isfinite(f.get(names["power"]))
        if wind == 0.0 and rpm == 0.0:
            assert f.get(names["power"]) == 0.0


# ------------------------------------------------------------------ stepping
@pytest.mark.parametrize("variant", ["A", "B"])
def test_do_step_checks_the_communication_point(open_fmu, variant):
    """doStep must continue from the FMU's own time: a gap or a step back is an error (with
    a message), and the refused call changes nothing."""
    names = NAMES[variant]
    f = open_fmu(variant)
    f.initialize(start_time=2.0)
    f.step(0.05)                                   # 2.0 -> 2.05
    p = f.get(names["power"])
    for wrong in (2.05 + 1.0, 2.0, 0.0, 2.05 + 1e-6):
        with pytest.raises(FMICallException):
            f.step(0.05, current=wrong)
        assert "currentCommunicationPoint" in f.errors()
    assert f.get(names["power"]) == p
    f.step(0.05, current=2.05 + 1e-12)             # rounding of the caller's clock is fine
    assert f.time == pytest.approx(2.1)


@pytest.mark.parametrize("variant", ["A", "B"])
def test_sub_steps_per_do_step_are_capped(open_fmu, variant):
    """One doStep may take at most 10 000 internal steps (default internal step 0.02 s:
    200 s); longer communication steps, including absurd ones (1e300 s), are refused."""
    f = open_fmu(variant)
    f.initialize()
    for h in (10000 * 0.02 * 1.01, 1e300):
        with pytest.raises(FMICallException):
            f.step(h, current=0.0)
        assert "10000" in f.errors()
    f.step(1.0, current=0.0)                       # 50 internal steps: fine
