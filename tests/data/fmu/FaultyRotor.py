"""A vendor FMU with faults built in, for the fault tests and benchmark (PythonFMU, FMI 2.0).

Built at test time (``pythonfmu build -f FaultyRotor.py --handle-state --serialize-state``);
never committed as an FMU. Inputs: wind speed ``v`` [m/s], rotor speed ``rpm`` [rpm], pitch
``pitch`` [deg]. Tunable parameters: ``cp_gain``, ``ct_gain`` [-], ``pitch_bias`` [deg] and
``tsr_opt`` [-] (tip speed ratio of the power peak). Outputs ``power`` [W] and ``thrust`` [N]
follow the quasi-steady values

    P = 1/2 rho A V^3 cp_gain 0.47 exp(-((lambda - tsr_opt)/3)^2 / 2) cos^2(beta + pitch_bias)
    T = 1/2 rho A V^2 ct_gain 0.85 (1 - exp(-lambda/4)) cos(beta + pitch_bias)

(lambda = omega R / V, R = 40 m, rho = 1.225 kg/m^3) through a first-order lag of 0.5 s, so a
simulation has to settle.

Faults, each at one wind speed (fixed parameters [m/s], matched within 1e-6 m/s; a negative
value switches the fault off, the default), checked at every step, so a run meets it at its first:

- ``crash_wind_speed``: ``os.abort()`` (SIGABRT: the process hosting the FMU dies);
- ``hang_wind_speed``: ``do_step`` never returns (sleeps for an hour);
- ``error_wind_speed``: ``do_step`` refuses the step (returns False, which PythonFMU 0.7
  returns as ``fmi2Discard``: an error status, the instance and the process live on; PythonFMU
  has no way to return ``fmi2Error`` itself);
- ``fatal_wind_speed``: ``do_step`` raises, which PythonFMU returns as ``fmi2Fatal`` (after
  which FMI allows no further call of any instance).

``step_cost`` [s] (fixed parameter, default 0) busy-waits that long at every step, to give a
healthy simulation the cost of a real aeroelastic FMU. If the environment variable
``FAULTY_ROTOR_LOG`` names a file, every fault appends one line ``<kind> <wind speed> <rotor
speed> <pitch> <pid>`` to it before it happens: the tests count simulations of the faulty
points from outside calib.
"""

import math
import os
import time

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

RADIUS = 40.0
TIME_CONSTANT = 0.5
MATCH = 1e-6          # [m/s]


def _log_fault(kind: str, slave) -> None:
    path = os.environ.get("FAULTY_ROTOR_LOG")
    if path:
        with open(path, "a") as fh:
            fh.write(f"{kind} {slave.v:.6f} {slave.rpm:.6f} {slave.pitch:.6f} {os.getpid()}\n")


class FaultyRotor(Fmi2Slave):
    author = "calib tests"
    description = "Test rotor with a crash, a hang and an error at chosen wind speeds"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.v = 8.0
        self.rpm = 15.0
        self.pitch = 0.0
        self.cp_gain = 1.0
        self.ct_gain = 1.0
        self.pitch_bias = 0.0
        self.tsr_opt = 8.0
        self.crash_wind_speed = -1.0
        self.hang_wind_speed = -1.0
        self.error_wind_speed = -1.0
        self.fatal_wind_speed = -1.0
        self.step_cost = 0.0
        self.power = 0.0
        self.thrust = 0.0
        for name in ("v", "rpm", "pitch"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("cp_gain", "ct_gain", "pitch_bias", "tsr_opt"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for name in ("crash_wind_speed", "hang_wind_speed", "error_wind_speed", "fatal_wind_speed", "step_cost"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed))
        for name in ("power", "thrust"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def _refuse(self) -> bool:
        """Crash or hang at their wind speeds, raise at the fatal one; True: refuse the step."""
        v = self.v
        if abs(v - self.crash_wind_speed) < MATCH:
            _log_fault("crash", self)
            os.abort()
        if abs(v - self.hang_wind_speed) < MATCH:
            _log_fault("hang", self)
            time.sleep(3600.0)
        if abs(v - self.fatal_wind_speed) < MATCH:
            _log_fault("fatal", self)
            raise RuntimeError(f"FaultyRotor: exception at wind speed {v:g} m/s (by design)")
        if abs(v - self.error_wind_speed) < MATCH:
            _log_fault("error", self)
            return True
        return False

    def do_step(self, current_time, step_size):
        if self._refuse():
            return False
        if self.step_cost > 0:
            end = time.perf_counter() + self.step_cost
            while time.perf_counter() < end:
                pass
        v = self.v
        lam = self.rpm * math.pi / 30.0 * RADIUS / v
        b = math.radians(self.pitch + self.pitch_bias)
        cp = self.cp_gain * 0.47 * math.exp(-0.5 * ((lam - self.tsr_opt) / 3.0) ** 2) * math.cos(b) ** 2
        ct = self.ct_gain * 0.85 * (1.0 - math.exp(-lam / 4.0)) * math.cos(b)
        q = 0.5 * 1.225 * math.pi * RADIUS ** 2
        k = 1.0 - math.exp(-step_size / TIME_CONSTANT)
        self.power += (q * v ** 3 * cp - self.power) * k
        self.thrust += (q * v ** 2 * ct - self.thrust) * k
        return True
