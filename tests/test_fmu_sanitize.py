"""No undefined behaviour and no memory errors in the rotor FMUs, even on bad input.

Both variants are built once with ``-fsanitize=address,undefined`` (+ float-cast-overflow,
every report fatal; ``build_fmu(variant, sanitize=True)``, a separate cache entry) and driven
in a child Python process that preloads the ASan runtime (``sanitizer_environment``):
normal steps, the extremes of every range, everything the FMUs must refuse (absurd values,
partial array sets, wrong communication points, too many sub-steps, a 1e300 s step, states
of another build or edited), standstill, zero wind, a yawed case where the in-plane velocity
reverses at the root, state round trips, reset. Any sanitizer report aborts the child and
fails the test.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from calib.fmu.build import build_fmu, sanitizer_environment

TESTS = os.path.dirname(os.path.abspath(__file__))

SCENARIO = r'''
import struct, sys
import numpy as np
from fmpy.fmi1 import FMICallException
from test_fmu_inputs import NAMES, Fmu
from test_fmu_state import serialize, restore, with_checksum, HEADER_BYTES

paths = {"A": sys.argv[1], "B": sys.argv[2]}
refused = 0

def refuse(call, *args, **kw):
    global refused
    try:
        call(*args, **kw)
    except FMICallException:
        refused += 1
        return
    raise AssertionError(f"{call.__name__} was accepted: {str(args)[:200]} {kw}")

def run(f, n, h=0.05):
    for _ in range(n):
        f.step(h)
    return f.get(NAMES[f.variant]["power"])

def ranged(f):
    """(name, min, max) of every input and Real/Integer parameter."""
    return [(v.name, float(v.min), float(v.max)) for v in f.md.modelVariables
            if v.causality in ("input", "parameter") and v.min is not None]

states = {}
for variant in "AB":
    n = NAMES[variant]
    f = Fmu(paths[variant], variant)
    f.slave.setDebugLogging(True, [])
    # every parameter at its minimum, then at its maximum (where the core accepts the mix)
    for pick in (1, 2):
        g = Fmu(paths[variant], variant)
        for name, lo, hi in ranged(g):
            if name.startswith(("Tower", "tower")):  # keep the tower below the rotor
                continue
            g.set(**{name: np.full(g.size(name), (lo, hi)[pick - 1]) if g.size(name) > 1 else (lo, hi)[pick - 1]})
        try:
            g.initialize()
            run(g, 3)
        except FMICallException:
            pass                                   # refused combinations are fine; UB is not
        g.slave.freeInstance()
    # refused values, before and after initialization
    for q, value in (("tilt", 90.0), ("wind", -1.0), ("blades", 1000), ("density", float("nan"))):
        refuse(f.set, **{n[q]: value})
    f.initialize()
    run(f, 5)
    for q, value in (("rotor_speed", -9.0), ("dcd", -5.0), ("pitch_offset", 1e6), ("dcl", float("inf"))):
        refuse(f.set, **{n[q]: np.full(f.size(n[q]), value) if f.size(n[q]) > 1 else value})
    if variant == "B":
        bad = np.zeros(f.size(n["dcd"])); bad[-1] = -5.0
        refuse(f.set, **{n["dcd"]: bad})
    refuse(f.step, 0.05, current=f.time + 1.0)
    refuse(f.step, 1e300)
    refuse(f.step, 10000 * 0.02 * 1.01)
    refuse(f.step, -0.05)
    run(f, 3)
    # zero wind, standstill, extremes of the inputs, yaw with root reversal
    for wind, rpm, yaw, pitch in ((0.0, 9.0, 0.0, 0.0), (0.0, 0.0, 60.0, 90.0), (50.0, 100.0, -60.0, -30.0),
                                  (20.0, 12.1, 20.0, 17.5), (3.0, 0.0, 0.0, 0.0)):
        f.set(**{n["wind"]: wind, n["rotor_speed"]: rpm * n["rpm"],
                 ("yaw_error" if variant == "A" else "Wind.YawMisalignment"): yaw,
                 ("collective_pitch" if variant == "A" else "Control.PitchAngle"): pitch})
        try:
            run(f, 4)
        except FMICallException:
            f.slave.reset(); f.initialize()
    states[variant], t_saved = serialize(f), f.time
    # edited states (checksum fixed): refused, or accepted and then stepped or refused -- never UB
    blob = states[variant]
    for at in range(HEADER_BYTES, len(blob) - 8, 8 * 61):
        for value in (float("nan"), 1e308, -1000.0):
            try:
                restore(f, with_checksum(blob[:at] + struct.pack("<d", value) + blob[at + 8:]))
                f.time = t_saved
                run(f, 2)
            except FMICallException:
                pass
    refuse(restore, f, blob[:-8])                                   # truncated
    refuse(restore, f, blob[:HEADER_BYTES - 1] + b"\x01" + blob[HEADER_BYTES:])   # header edited
    refuse(restore, f, blob[:HEADER_BYTES] + bytes([blob[HEADER_BYTES] ^ 0xFF]) + blob[HEADER_BYTES + 1:])
    restore(f, blob)
    f.time = t_saved
    run(f, 3)
    f.slave.reset()
    f.initialize()
    run(f, 2)
    f.slave.terminate()
    f.slave.freeInstance()
# a state of the other build
for source, target in (("A", "B"), ("B", "A")):
    f = Fmu(paths[target], target).initialize()
    refuse(restore, f, states[source])
    run(f, 1)
    f.slave.freeInstance()
print("DONE", refused)
'''


@pytest.fixture(scope="module")
def sanitized_fmus():
    """Both variants with AddressSanitizer and UBSan (built once, cached apart from the others)."""
    return {v: build_fmu(v, sanitize=True) for v in ("A", "B")}


def test_no_sanitizer_report_on_good_and_bad_input(sanitized_fmus):
    env = sanitizer_environment()
    env["PYTHONPATH"] = os.pathsep.join([TESTS] + [p for p in (env.get("PYTHONPATH"),) if p])
    proc = subprocess.run([sys.executable, "-c", SCENARIO, str(sanitized_fmus["A"]), str(sanitized_fmus["B"])],
                          cwd=TESTS, env=env, capture_output=True, text=True, timeout=600)
    report = proc.stdout[-3000:] + proc.stderr[-6000:]
    assert "runtime error" not in proc.stderr and "Sanitizer" not in proc.stderr, report
    assert proc.returncode == 0, report
    done = [line for line in proc.stdout.splitlines() if line.startswith("DONE")]
    assert done and int(done[0].split()[1]) >= 30, report   # the bad inputs were exercised (and refused)


def test_sanitizer_catches_undefined_behaviour(tmp_path):
    """The set-up can fail: a float-to-int conversion of NaN (what the polar lookup did) in a
    small library built with the same flags and loaded the same way aborts the child."""
    from calib.fmu.build import SANITIZE_FLAGS, find_tools
    _, cc = find_tools()
    src = tmp_path / "ub.c"
    src.write_text("#include <math.h>\nint to_index(double x) { return (int)floor(x); }\n")
    lib = tmp_path / "libub.so"
    subprocess.run([cc, "-shared", "-fPIC", *SANITIZE_FLAGS.split(), str(src), "-o", str(lib), "-lm"], check=True)
    code = (f"import ctypes; f = ctypes.CDLL({str(lib)!r}).to_index; f.argtypes = [ctypes.c_double]; "
            "print(f(1.5)); print(f(float('nan')))")
    proc = subprocess.run([sys.executable, "-c", code], env=sanitizer_environment(), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode != 0 and "runtime error" in proc.stderr, proc.stderr[-2000:]
