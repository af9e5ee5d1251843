"""One FMU instance driven in this process through fmpy (:class:`Simulator`).

Instantiate once, ``reset`` between runs, settle, average over whole revolutions
(:mod:`calib.fmu.windows`), save / restore / serialize the FMU state, and turn what the FMU
reports into a per-run status. :mod:`calib.fmu.worker` runs it in a child process.
"""

from __future__ import annotations

import ctypes
import logging
import struct
import time

import numpy as np

from calib.fmu.plan import FMI_FATAL, PointResult, PointTask, RunOutcome, SimulationPlan
from calib.fmu.settling import settled_window
from calib.fmu.windows import convergence_failures, window_statistics
from calib.types import Status

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- in-process driver
class Simulator:
    """One FMU instance in this process, driven through a :class:`SimulationPlan`.

    The instance is created on first use and reused: ``reset`` before every cold run; after
    an error the instance is freed and created again (a vendor FMU may be unusable after
    an error). After a fatal status ``fatal`` is set: FMI allows no further call of any
    instance, so a worker process ends (:func:`calib.fmu.child.child_main`); in process, the instance is
    created again as after an error (nothing better is possible there). FMU log messages are
    kept (the last 20) and quoted in failure messages. ``notify`` (a callable, optional)
    receives ``("instantiating",)`` and ``("instantiated", seconds)`` around the creation of
    an instance, so that a supervisor can time it apart from the simulation.
    """

    def __init__(self, plan: SimulationPlan):
        self.plan = plan
        self.fmu = None
        self._healthy = False
        self._log: list[str] = []
        self._callbacks = None
        self._buffer = (ctypes.c_double * max(plan.read_count, 1))()
        self._vr_array = (ctypes.c_uint * max(len(plan.read_vrs), 1))(*plan.read_vrs)
        self._fmi3 = plan.fmi_version.startswith("3")
        self.instantiations = 0
        self.last_instantiation = 0.0
        self.fatal = False
        self.notify = None

    # -- lifecycle ----------------------------------------------------------------
    def _logger2(self, env, instance_name, status, category, message):
        self._remember(status, category, message)

    def _logger3(self, env, status, category, message):
        self._remember(status, category, message)

    def _remember(self, status, category, message):
        text = message.decode("utf-8", "replace") if isinstance(message, bytes) else str(message)
        label = ["OK", "WARNING", "DISCARD", "ERROR", "FATAL", "PENDING"][min(int(status), 5)]
        self._log.append(f"[{label}] {text}")
        del self._log[:-20]

    def _instantiate(self):
        t0 = time.perf_counter()
        if self.notify is not None:
            self.notify(("instantiating",))
        self._create_instance()
        self.last_instantiation = time.perf_counter() - t0
        if self.notify is not None:
            self.notify(("instantiated", self.last_instantiation))

    def _create_instance(self):
        p = self.plan
        if self._fmi3:
            from fmpy.fmi3 import FMU3Slave, fmi3LogMessageCallback  # noqa: F401
            fmu = FMU3Slave(guid=p.guid, unzipDirectory=p.unzip_dir, modelIdentifier=p.model_identifier,
                            instanceName=p.instance_name)
            fmu.instantiate(loggingOn=False, logMessage=self._logger3)
        else:
            from fmpy.fmi2 import (FMU2Slave, calloc, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                                   fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, free)
            fmu = FMU2Slave(guid=p.guid, unzipDirectory=p.unzip_dir, modelIdentifier=p.model_identifier,
                            instanceName=p.instance_name)
            cb = fmi2CallbackFunctions()
            cb.logger = fmi2CallbackLoggerTYPE(self._logger2)
            cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
            cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
            self._callbacks = cb
            fmu.instantiate(callbacks=cb)
        self.fmu = fmu
        self.instantiations += 1
        self._healthy = True

    def close(self):
        """Free the instance. The shared library stays loaded: another instance of the same
        FMU in this process may share its handle (unloading it crashed that one)."""
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except Exception:  # noqa: BLE001 - an instance in error may refuse terminate
                pass
            try:
                self.fmu.freeInstance()
            except Exception:  # noqa: BLE001
                pass
        self.fmu = None
        self._healthy = False

    def _fresh(self):
        """An instance ready for initialization: reset the existing one, or create one."""
        self._log.clear()
        if self.fmu is not None and self._healthy:
            try:
                self.fmu.reset()
                return
            except Exception:  # noqa: BLE001 - rebuild below
                pass
        self.close()
        self._instantiate()

    # -- FMI calls ----------------------------------------------------------------
    def _set(self, assignments):
        f = self.fmu
        for a in assignments:
            vrs = list(a.vrs)
            if a.type == "real":
                (f.setFloat64 if self._fmi3 else f.setReal)(vrs, list(a.values))
            elif a.type == "integer":
                (f.setInt32 if self._fmi3 else f.setInteger)(vrs, [int(v) for v in a.values])
            else:
                f.setBoolean(vrs, [bool(v) for v in a.values])

    def _read(self) -> np.ndarray:
        p = self.plan
        if self._fmi3:
            self.fmu.fmi3GetFloat64(self.fmu.component, self._vr_array, len(p.read_vrs), self._buffer, p.read_count)
        else:
            self.fmu.fmi2GetReal(self.fmu.component, self._vr_array, len(p.read_vrs), self._buffer)
        return np.frombuffer(self._buffer, dtype=np.float64, count=p.read_count).copy()

    def _counters(self) -> np.ndarray:
        out = []
        for c in self.plan.counters:
            if c.type == "real":
                v = (self.fmu.getFloat64 if self._fmi3 else self.fmu.getReal)([c.vr])[0]
            else:
                v = (self.fmu.getInt32 if self._fmi3 else self.fmu.getInteger)([c.vr])[0]
            out.append(float(v))
        return np.array(out)

    def _step(self, t: float, h: float):
        self.fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)

    def _initialize(self, start_time: float):
        if self._fmi3:
            self.fmu.enterInitializationMode(startTime=start_time)
        else:
            self.fmu.setupExperiment(startTime=start_time)
            self.fmu.enterInitializationMode()

    def _exit_initialization(self):
        self.fmu.exitInitializationMode()

    def get_state(self):
        return self.fmu.getFMUState() if self._fmi3 else self.fmu.getFMUstate()

    def set_state(self, state):
        if self._fmi3:
            self.fmu.setFMUState(state)
        else:
            self.fmu.setFMUstate(state)

    def free_state(self, state):
        try:
            if self._fmi3:
                self.fmu.freeFMUState(state)
            else:
                self.fmu.freeFMUstate(state)
        except Exception:  # noqa: BLE001
            pass

    def serialize(self, state) -> bytes:
        data = self.fmu.serializeFMUState(state) if self._fmi3 else self.fmu.serializeFMUstate(state)
        return bytes(data)

    def deserialize(self, data: bytes):
        return self.fmu.deserializeFMUState(data) if self._fmi3 else self.fmu.deSerializeFMUstate(data)

    # -- runs ---------------------------------------------------------------------
    def _window(self, t: float, h: float, n_settle: int, n_average: int):
        """Settle ``n_settle`` steps, then sample ``n_average`` steps; returns (samples, sample
        times, counter increases over the window, end time)."""
        p = self.plan
        for _ in range(n_settle):
            self._step(t, h)
            t += h
        c0 = self._counters()
        raw = np.empty((n_average, p.read_count))
        times = np.empty(n_average)
        for k in range(n_average):
            self._step(t, h)
            t += h
            raw[k] = self._read()
            times[k] = t
        return raw, times, self._counters() - c0, t

    def _signals(self, raw: np.ndarray) -> np.ndarray:
        """The samples ``raw`` (n_samples, read_count) as the plan's signals in package units."""
        sig = self.plan.signals
        x = np.empty((raw.shape[0], len(sig)))
        for i, s in enumerate(sig):
            y = s.sign * (s.scale * raw[:, s.index] + s.offset)
            x[:, i] = np.mod(y, s.wrap) if s.wrap else y
        return x

    def _outcome(self, raw, times, counters, rotor_speed, steps, t0_wall, check: bool = True) -> RunOutcome:
        p = self.plan
        x = self._signals(raw)
        if not rotor_speed > 0:
            psi = None                                    # standstill: no harmonics
        elif p.azimuth is not None:
            psi = np.radians(x[:, p.azimuth])
        else:                                             # no azimuth output: from the rotor speed, 0 at t = 0
            psi = 2.0 * np.pi * rotor_speed / 60.0 * times
        mean, halves, harm = window_statistics(x, psi)
        names = [s.name for s in p.signals]
        status, message = Status.CONVERGED, ""
        if not np.all(np.isfinite(x[:, list(p.checked)])):
            status, message = Status.SIMULATION_FAILED, "non-finite output in the averaging window"
        elif check:
            bad = convergence_failures(mean, halves, x, p.steady.convergence_rtol, p.checked, names)
            if bad:
                status, message = Status.NOT_STEADY, "averages not converged: " + "; ".join(bad)
        cnt = {c.name: float(v) for c, v in zip(p.counters, counters)}
        failures = {k: v for k, v in cnt.items() if v > 0}
        if failures and status == Status.CONVERGED:
            status = Status.NOT_CONVERGED
            message = "; ".join(f"{k} rose by {v:g} in the averaging window" for k, v in failures.items())
        return RunOutcome(int(status), message, mean, halves, harm, cnt, steps, time.perf_counter() - t0_wall)

    def _failure(self, exc: BaseException, what: str, t0_wall: float) -> RunOutcome:
        self._healthy = False
        self.fatal = self.fatal or getattr(exc, "status", None) == FMI_FATAL
        fmu_log = " | ".join(m for m in self._log if not m.startswith("[OK]"))[-600:]
        msg = f"{what}: {type(exc).__name__}: {exc}" + (f"; FMU log: {fmu_log}" if fmu_log else "")
        return RunOutcome.failed(len(self.plan.signals), Status.SIMULATION_FAILED, msg,
                                 time.perf_counter() - t0_wall, "fatal" if self.fatal else "error")

    def cold_run(self, task: PointTask, parameters, keep_state: bool):
        """Reset, set everything, initialize, settle (optionally save the state), average.

        With ``steady.settle_rtol`` a run from scratch settles until its window's own check holds
        (:func:`calib.fmu.settling.settled_window`), at most ``settle_revolutions``; its ``steps`` say how far.

        Returns
        -------
        outcome : RunOutcome
        state : FMU state handle or None
            The settled state (before the averaging window), when ``keep_state``.
        state_time : float
            Simulation time of that state [s].
        """
        t0_wall = time.perf_counter()
        h, n_settle, n_average = self.plan.steady.window(task.rotor_speed)
        state, t_state, created = None, 0.0, self.instantiations
        try:
            self._fresh()
            t = 0.0
            if task.start_state is not None:           # from a saved settled state
                _, n_settle, _ = self.plan.steady.perturbation_window(task.rotor_speed)
                start, t = self._restore_point(task.start_state)
                self.set_state(start)
                self.free_state(start)
                self._set(parameters)
                self._set(task.inputs)
            else:
                self._set(self.plan.fixed)
                self._set(parameters)
                self._set(task.inputs)
                self._initialize(0.0)
                self._exit_initialization()
            if self.plan.steady.settle_rtol is not None and task.start_state is None:
                # settled until its own check holds: the state kept is the run's last (settled at least as far)
                raw, times, counters, t, n_settle = settled_window(self, t, h, n_settle, n_average)
                if keep_state:
                    state, t_state = self.get_state(), t
            else:
                _, _, _, t = self._window(t, h, n_settle, 0)
                if keep_state:
                    state, t_state = self.get_state(), t
                raw, times, counters, t = self._window(t, h, 0, n_average)
        except Exception as exc:  # noqa: BLE001 - an FMU error is this run's status
            return self._failure(exc, "simulation failed", t0_wall), None, 0.0
        outcome = self._outcome(raw, times, counters, task.rotor_speed, n_settle + n_average, t0_wall)
        outcome.instantiation = self.last_instantiation if self.instantiations != created else 0.0
        outcome.simulated = (n_settle + n_average) * h
        return outcome, state, t_state

    def warm_run(self, task: PointTask, parameters, state, state_time: float) -> RunOutcome:
        """Restore the settled base state, set the (perturbed) parameters, settle, average."""
        t0_wall = time.perf_counter()
        h, n_settle, n_average = self.plan.steady.perturbation_window(task.rotor_speed)
        try:
            self.set_state(state)
            self._set(parameters)
            raw, times, counters, _ = self._window(state_time, h, n_settle, n_average)
        except Exception as exc:  # noqa: BLE001
            return self._failure(exc, "perturbed simulation (restored state) failed", t0_wall)
        # the halves of an odd number of revolutions are not whole revolutions: no check then (the
        # base run of the point was checked)
        check = self.plan.steady.perturbation_average_revolutions % 2 == 0
        outcome = self._outcome(raw, times, counters, task.rotor_speed, n_settle + n_average, t0_wall, check)
        outcome.simulated = (n_settle + n_average) * h
        return outcome

    def _restore_point(self, blob: bytes):
        """A state handle in a healthy instance from serialized bytes (+ its time)."""
        if self.fmu is None or not self._healthy:
            self._fresh()
        return self.deserialize(blob[:-8]), struct.unpack("<d", blob[-8:])[0]

    def runs(self, task: PointTask):
        """Generator of the runs of a point: ``("base", outcome, state_bytes)`` first (unless
        resuming from ``task.base_state``), then ``("run", j, outcome)`` per perturbation.

        Perturbed runs restore the settled base state when the FMU can get/set states and
        ``task.warm``; if the instance had to be rebuilt after an error, the state comes back
        from its serialized bytes; without those the perturbed runs start cold.
        """
        p = self.plan
        warm = p.can_get_state and ((task.warm and bool(task.perturbations)) or task.keep_state)
        state, t_state, blob, owner = None, 0.0, task.base_state, None
        if task.known_base is not None and task.base_state is None:   # simulated before: perturbed runs cold
            warm = False
            yield ("base", task.known_base, None)
            if not task.known_base.ok:
                return
        elif task.base_state is None:
            outcome, state, t_state = self.cold_run(task, task.base, keep_state=warm)
            owner = self.instantiations
            if state is not None and p.can_serialize:
                try:
                    blob = self.serialize(state) + struct.pack("<d", t_state)
                except Exception:  # noqa: BLE001 - resumption then starts cold
                    blob = None
            yield ("base", outcome, blob)
            if not outcome.ok:
                if state is not None:
                    self.free_state(state)
                return
        for j in range(task.skip, len(task.perturbations)):
            outcome = None
            if not warm and task.known_runs is not None and task.known_runs[j] is not None:
                yield ("run", j, task.known_runs[j])      # a cold run at these parameters, simulated before
                continue
            if warm and (state is None or owner != self.instantiations or not self._healthy) and blob is not None:
                try:
                    state, t_state = self._restore_point(blob)
                    owner = self.instantiations
                except Exception:  # noqa: BLE001 - cold below
                    state = None
            if warm and state is not None and owner == self.instantiations:
                outcome = self.warm_run(task, task.perturbations[j], state, t_state)
            if outcome is None:
                outcome, _, _ = self.cold_run(task, task.perturbations[j], keep_state=False)
            yield ("run", j, outcome)
        if state is not None and owner == self.instantiations and self._healthy:
            self.free_state(state)

    def probe(self, reads) -> list:
        """Initialize with the fixed settings and read ``reads`` = [(vr, n_values), ...]."""
        self._fresh()
        self._set(self.plan.fixed)
        self._initialize(0.0)
        self._exit_initialization()
        out = []
        for vr, n in reads:
            out.append(list(self.fmu.getFloat64([vr], nValues=n) if self._fmi3 else self.fmu.getReal([vr])))
        return out

    def run_point(self, task: PointTask) -> PointResult:
        """All runs of a point in this process (no timeout, no protection from crashes)."""
        res = PointResult(task.index, None, [None] * len(task.perturbations))
        for msg in self.runs(task):
            if msg[0] == "base":
                res.base, res.base_state = msg[1], msg[2]
            else:
                res.perturbations[msg[1]] = msg[2]
        return res


