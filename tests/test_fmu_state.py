"""FMU states of the rotor FMUs: a saved state continues a simulation exactly, and a
serialized state carries its build's identity and is validated before it is restored.

Serialized layout (``fmu_models/README.md``, "FMU state"): a header
``magic[24] | format u32 | header_bytes u32 | payload_bytes u64 | checksum u64 (FNV-1a 64
of the payload) | token[64]`` (112 bytes), then the payload (the core's dynamic part).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest

from fmpy.fmi1 import FMICallException

from test_fmu_inputs import NAMES, Fmu

HEADER_BYTES = 112
CHECKSUM_AT = 40


def fnv1a64(data: bytes) -> int:
    h = 14695981039346656037
    for byte in data:
        h = ((h ^ byte) * 1099511628211) & 0xFFFFFFFFFFFFFFFF
    return h


def with_checksum(blob: bytes) -> bytes:
    """The blob with its header checksum recomputed (what a careful forger would do)."""
    return blob[:CHECKSUM_AT] + struct.pack("<Q", fnv1a64(blob[HEADER_BYTES:])) + blob[CHECKSUM_AT + 8:]


def serialize(f: Fmu) -> bytes:
    state = f.slave.getFMUState()
    blob = f.slave.serializeFMUState(state)
    f.slave.freeFMUState(state)
    return blob


def restore(f: Fmu, blob: bytes):
    deserialize = f.slave.deSerializeFMUstate if f.variant == "A" else f.slave.deserializeFMUState
    state = deserialize(blob)
    f.slave.setFMUState(state)
    f.slave.freeFMUState(state)


def outputs(f: Fmu) -> np.ndarray:
    n = NAMES[f.variant]
    return np.array([f.get(n["power"]), f.get("azimuth" if f.variant == "A" else "Rotor.Azimuth")])


@pytest.fixture
def opened(fmus):
    made = []

    def make(variant):
        made.append(Fmu(fmus[variant], variant))
        return made[-1]
    yield make
    for f in made:
        f.slave.freeInstance()


@pytest.mark.parametrize("variant", ["A", "B"])
def test_serialized_state_round_trips(opened, variant):
    """Serialize after 20 steps, run 20 more; restoring the bytes (in the same instance and in
    a fresh one, as a worker would) and running the same 20 steps gives identical outputs."""
    f = opened(variant).initialize()
    for _ in range(20):
        f.step(0.05)
    blob = serialize(f)
    assert blob[:17] == b"calib-rotor-state"
    assert struct.unpack_from("<I", blob, 28)[0] == HEADER_BYTES
    assert struct.unpack_from("<Q", blob, 32)[0] == len(blob) - HEADER_BYTES
    for _ in range(20):
        f.step(0.05)
    reference = outputs(f)
    restore(f, blob)
    f.time = 1.0
    for _ in range(20):
        f.step(0.05)
    assert np.array_equal(outputs(f), reference)
    fresh = opened(variant)                   # instantiated, never initialized
    restore(fresh, blob)
    fresh.time = 1.0
    for _ in range(20):
        fresh.step(0.05)
    assert np.array_equal(outputs(fresh), reference)


@pytest.mark.parametrize("source,target", [("A", "B"), ("B", "A")])
def test_state_of_another_build_is_refused(opened, source, target):
    """Both variants share the core, so their states have the same size: only the build's
    GUID / instantiation token in the header tells them apart."""
    a = opened(source).initialize()
    a.step(0.05)
    blob = serialize(a)
    b = opened(target).initialize()
    b.step(0.05)
    before = outputs(b)
    with pytest.raises(FMICallException):
        restore(b, blob)
    assert "another build" in b.errors(), b.errors()
    assert np.array_equal(outputs(b), before)
    b.step(0.05)                               # the target goes on unharmed


def _offset_of(opened, variant, name, value) -> int:
    """Byte offset of a parameter in the serialized state: diff two fresh instances that
    differ only in that parameter."""
    base, other = opened(variant), opened(variant)
    other.set(**{name: value})
    x, y = np.frombuffer(serialize(base), np.uint8), np.frombuffer(serialize(other), np.uint8)
    diff = np.flatnonzero(x[HEADER_BYTES:] != y[HEADER_BYTES:]) + HEADER_BYTES
    assert diff.size and diff.max() - diff.min() < 8, diff
    return int(diff.min()) // 8 * 8


@pytest.mark.parametrize("variant", ["A", "B"])
@pytest.mark.parametrize("field,value", [("blades", 1000.0), ("blades", 2.5), ("density", -1.0),
                                         ("density", float("nan"))])
def test_edited_state_is_refused_without_crash(opened, variant, field, value):
    """A state whose number of blades is edited to 1000 used to crash doStep (arrays sized for
    3 blades). Edited states are refused, by the checksum and, if the forger fixed that, by
    the range checks; the instance keeps working."""
    names = NAMES[variant]
    probe = {"blades": 2, "density": 1.1}[field]
    at = _offset_of(opened, variant, names[field], probe)
    f = opened(variant).initialize()
    for _ in range(5):
        f.step(0.05)
    blob = serialize(f)
    edited = blob[:at] + struct.pack("<d", value) + blob[at + 8:]
    for bad, why in ((edited, "checksum"), (with_checksum(edited), "invalid values")):
        with pytest.raises(FMICallException):
            restore(f, bad)
        assert why in f.errors(), f.errors()
    for _ in range(5):
        f.step(0.05)
    assert np.isfinite(f.get(names["power"]))
    restore(f, blob)                           # the genuine state still restores


@pytest.mark.parametrize("variant", ["A", "B"])
def test_a_reset_instance_runs_bit_for_bit_as_a_fresh_one(fmus, variant):
    """One instance per worker, ``reset`` between runs (issue 38): the runs of a point after the instance ran
    other points and parameters are, bit for bit, those of a fresh instance, with the physics on whose state a
    stale run would carry over (Øye inflow, flexible blades, tower shadow, shear, gravity, shaft tilt)."""
    from calib.fmu.build import mapping_path
    from calib.fmu.model import FmuModel
    from calib.fmu.simulator import Simulator
    from calib.types import OperatingConditions

    names = ["pitch_offset_blade1", "stall_delay_strength"]
    m = FmuModel(fmus[variant], mapping_path(variant), ["power", "thrust", "root_flap_moment_blade1"],
                 parameters=names, corrections=False, isolate=False,
                 switches=dict(dynamic_inflow=True, flexible_blades=True, tower_shadow=True, shear=True, gravity=True,
                               stall_delay="snel"),
                 steady=dict(steps_per_revolution=8, settle_revolutions=1, average_revolutions=2),
                 jacobian=dict(differences="forward", warm_start=False))
    cond = OperatingConditions(np.array([6.0, 11.0, 8.0]), np.array([7.5, 11.5, 9.0]), np.array([2.0, 0.0, 1.0]))
    _, tasks, _ = m._tasks(np.array([0.3, 1.2]), cond, True)
    used, fresh = Simulator(m._plan), Simulator(m._plan)
    try:
        before = [used.run_point(t) for t in tasks[:2]]        # other points, other parameters
        again = used.run_point(tasks[2])
        first = fresh.run_point(tasks[2])
    finally:
        used.close()
        fresh.close()
        m.close()
    assert used.instantiations == 1 and fresh.instantiations == 1
    assert len(again.outcomes()) == 1 + len(names)
    for a, b in zip(again.outcomes(), first.outcomes()):
        assert a.ok and b.ok, (a.message, b.message)
        for field in ("mean", "halves", "harmonics"):
            assert np.array_equal(getattr(a, field), getattr(b, field)), field
        assert a.counters == b.counters
    assert not np.allclose(before[1].base.mean, again.base.mean)       # what came before differs from it
    assert not np.array_equal(again.perturbations[0].mean, again.base.mean)
