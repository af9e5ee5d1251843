"""FMU simulations for the adapter: one instance per worker, steady windows, faults survived.

Three layers, each usable alone, and the planner's record of faults:

- :class:`Simulator` drives one FMU instance in this process through fmpy: instantiate
  once, ``reset`` between runs, settle, average over whole revolutions, save / restore /
  serialize the FMU state, and turn what the FMU reports into a per-run status.
- :class:`WorkerProcess` runs a :class:`Simulator` in a child process (a new Python
  interpreter running :func:`child_main`) and talks to it over pipes. Every simulation has a
  timeout; an error status, a crash of the process (e.g. ``abort()`` in the FMU) or a hang
  becomes that run's status, the child is rebuilt (after a crash, a hang or a fatal
  status), and the runs still to do go on from the serialized settled state (so nothing
  computed before is lost). The timeout adapts (:func:`adaptive_timeout`) to the healthy
  runs measured by the planner (:class:`TimeoutPolicy`) and by the worker itself; creating
  the FMU instance is timed apart, against the start timeout.
- :func:`run_point` is what an executor maps over operating points: it gets a picklable
  :class:`SimulationPlan` and :class:`PointTask` (paths and values, never an instance) and
  uses the worker of the current process (one per plan, kept for later tasks).
- :class:`calib.models.fmu_faults.FaultLedger` lives with the model, where tasks are
  planned: it quarantines points that crashed or hung, so that later calls do not simulate
  them again, and keeps the healthy wall times that set the timeout.

Statistics of a run (:func:`window_statistics`): over the averaging window of N samples
(equally spaced in azimuth, whole revolutions) the mean, the means of the two halves
(convergence check), and the complex harmonic coefficients
c_n = (2/N) Σ_k x_k exp(−i n ψ_k), n = 1, 2, 3, so that x ≈ mean + Σ_n |c_n| cos(nψ + arg c_n)
with ψ the azimuth of blade 1 (0 = up) [rad].
"""

from __future__ import annotations

import ctypes
import logging
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field, replace

import numpy as np

from calib.types import Status

HARMONIC_ORDERS = (1, 2, 3)
REAL_TYPES = ("Real", "Float64")
INTEGER_TYPES = ("Integer", "Int32", "Enumeration")
BOOLEAN_TYPES = ("Boolean",)

#: Time a simulation (and a worker's start) may take before it counts as hung [s], unless configured
DEFAULT_TIMEOUT = 60.0
#: Adaptive timeout: this multiple of the median wall time of healthy base runs [-] ...
TIMEOUT_MULTIPLE = 10.0
#: ... but never below this [s] (and never above the configured timeout)
TIMEOUT_FLOOR = 5.0
#: Healthy base-run wall times kept for the median (the most recent ones)
HEALTHY_WALLS_KEPT = 99
#: A quarantined point is retried (once) when a parameter has moved this many of its scales
RETRY_DISTANCE = 1.0
#: Faults that quarantine a point (expensive: a new process, a wait for the timeout)
QUARANTINE_FAULTS = ("crash", "timeout", "fatal")
#: fmi2Fatal / fmi3Fatal: no FMI call of any instance is allowed afterwards
FMI_FATAL = 4

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- plan and tasks
@dataclass(frozen=True)
class Assignment:
    """Values written to FMI variables of one type in one call.

    ``vrs`` are value references; ``values`` holds one value per scalar (FMI 2) or all
    elements of the arrays in order (FMI 3).
    """

    type: str                 # "real" | "integer" | "boolean"
    vrs: tuple[int, ...]
    values: tuple


@dataclass(frozen=True)
class Signal:
    """A signal read at every communication step, converted to package units."""

    name: str
    index: int                # position in the flat vector of Real / Float64 values read per step
    scale: float = 1.0
    offset: float = 0.0
    sign: int = 1
    wrap: float | None = None


@dataclass(frozen=True)
class Counter:
    """An integer output read at the start and end of the averaging window (e.g. solver failures)."""

    name: str
    vr: int
    type: str


@dataclass(frozen=True)
class SimulationPlan:
    """Everything a worker needs to simulate (picklable; no instance, no open library).

    Attributes
    ----------
    key : str
        Identity of the plan (FMU content hash and settings); workers are cached by it.
    fixed : tuple of Assignment
        Settings and switches, written after every reset before initialization.
    read_vrs, read_count : tuple of int, int
        Real outputs read per step in one call and the number of values they return.
    signals : tuple of Signal
    azimuth : int or None
        Index of the blade-1 azimuth signal [deg] in ``signals`` (harmonics and phases).
    checked : tuple of int
        Signals whose two half-window means must agree (convergence check).
    """

    key: str
    fmi_version: str
    model_identifier: str
    guid: str
    unzip_dir: str
    fixed: tuple[Assignment, ...]
    read_vrs: tuple[int, ...]
    read_count: int
    signals: tuple[Signal, ...]
    azimuth: int | None
    checked: tuple[int, ...]
    counters: tuple[Counter, ...]
    steady: object            # calib.models.fmu_mapping.SteadyRule
    can_get_state: bool
    can_serialize: bool
    instance_name: str = "calib"


@dataclass(frozen=True)
class PointTask:
    """The runs of one operating point: the base run, then perturbed runs.

    Attributes
    ----------
    index : int
        Position of the point in the batch.
    inputs : tuple of Assignment
        The operating condition (FMU values).
    base : tuple of Assignment
        The parameter values of the base run.
    perturbations : tuple of tuple of Assignment
        Parameter values of each perturbed run (all parameters, perturbed ones changed).
    rotor_speed : float
        [rpm], for the window.
    warm : bool
        Start perturbed runs from the base run's settled state (if the FMU can save it).
    base_state : bytes or None
        A serialized settled base state to resume from (the base run is then skipped).
    skip : int
        Number of perturbed runs already done (resume after a fault).
    keep_state : bool
        Return the serialized settled base state even without perturbations.
    start_state : bytes or None
        A serialized settled state (this build) the base run starts from instead of from
        scratch; it then settles only ``perturbation_settle_revolutions``.
    """

    index: int
    inputs: tuple[Assignment, ...]
    base: tuple[Assignment, ...]
    perturbations: tuple[tuple[Assignment, ...], ...] = ()
    rotor_speed: float = 0.0
    warm: bool = True
    base_state: bytes | None = None
    skip: int = 0
    keep_state: bool = False
    start_state: bytes | None = None


@dataclass
class RunOutcome:
    """Result of one simulation (a base or a perturbed run).

    Attributes
    ----------
    status : int
        :class:`calib.types.Status`.
    message : str
    mean : ndarray, shape (n_signals,)
        Window means in package units (NaN on failure).
    halves : ndarray, shape (2, n_signals)
    harmonics : ndarray of complex, shape (n_signals, 3)
        c_1, c_2, c_3 (see the module docstring); NaN at standstill.
    counters : dict
        Increase of each counter over the averaging window.
    steps : int
        Communication steps taken.
    wall : float
        [s], including ``instantiation``.
    fault : str
        ``""`` (no fault: converged, or a status computed from the outputs), ``"error"`` (an
        FMI call returned an error status or raised), ``"fatal"`` (an FMI call returned
        fmi2Fatal / fmi3Fatal: the worker process is replaced), ``"crash"`` (the process
        hosting the FMU died), ``"timeout"`` (the run hung), ``"start-timeout"`` (creating
        the instance exceeded the start timeout), ``"quarantined"`` (not simulated: see
        :class:`FaultLedger`).
    instantiation : float
        Part of ``wall`` spent creating the FMU instance [s] (0 when the instance was reused).
    """

    status: int
    message: str
    mean: np.ndarray
    halves: np.ndarray
    harmonics: np.ndarray
    counters: dict = field(default_factory=dict)
    steps: int = 0
    wall: float = 0.0
    fault: str = ""
    instantiation: float = 0.0

    @classmethod
    def failed(cls, n_signals: int, status: int, message: str, wall: float = 0.0, fault: str = "") -> "RunOutcome":
        nan = np.full(n_signals, np.nan)
        return cls(int(status), message, nan, np.full((2, n_signals), np.nan),
                   np.full((n_signals, len(HARMONIC_ORDERS)), np.nan + 0j), {}, 0, wall, fault)

    @property
    def ok(self) -> bool:
        return self.status == Status.CONVERGED


@dataclass
class PointResult:
    """The runs of one :class:`PointTask` (``perturbations[j]`` None if never run).

    ``timeout`` is the simulation timeout in force when the task ended [s] (None in
    process: no timeout).
    """

    index: int
    base: RunOutcome | None
    perturbations: list
    restarts: int = 0
    base_state: bytes | None = None
    timeout: float | None = None

    def outcomes(self) -> list:
        """The runs made, base first (perturbed runs never run left out)."""
        return [o for o in (self.base, *self.perturbations) if o is not None]


# ----------------------------------------------------------------------------- adaptive timeout
def adaptive_timeout(healthy_walls, configured: float, multiple: float = TIMEOUT_MULTIPLE,
                     floor: float = TIMEOUT_FLOOR) -> float:
    """Simulation timeout from the wall times of healthy runs.

    ``min(configured, max(floor, multiple * median(healthy_walls)))``; ``configured`` while
    no healthy run has been measured.

    Parameters
    ----------
    healthy_walls : sequence of float
        Wall times of converged base runs (cold, full window, instantiation excluded) [s].
    configured : float
        The user's timeout [s]: the rule never exceeds it.
    multiple : float
        [-]; 10 covers the spread of a healthy point's cost over the operating range and
        the slowdown of a loaded machine, and still stops a hang after ten healthy runs' worth.
    floor : float
        [s]; scheduling hiccups of a shared machine (seconds) must not kill a healthy run of
        a fast FMU (milliseconds).
    """
    walls = np.asarray(healthy_walls, float)
    if walls.size == 0:
        return float(configured)
    return float(min(configured, max(floor, multiple * float(np.median(walls)))))


@dataclass(frozen=True)
class TimeoutPolicy:
    """The timeouts a worker applies (picklable; sent with every task).

    Attributes
    ----------
    configured : float
        The user's timeout of one simulation [s] (the upper limit).
    multiple, floor : float
        Of :func:`adaptive_timeout` [-], [s].
    walls : tuple of float
        Healthy base-run wall times measured so far by the model (the planning process) [s].
    start_timeout : float
        Longest wall time for a worker process to start and for an FMU instance to be
        created [s]: instantiation is timed apart from the simulations.
    """

    configured: float
    multiple: float = TIMEOUT_MULTIPLE
    floor: float = TIMEOUT_FLOOR
    walls: tuple = ()
    start_timeout: float = DEFAULT_TIMEOUT

    def timeout(self, more=()) -> float:
        """The simulation timeout [s] from ``walls`` and ``more`` (a worker's own measurements)."""
        return adaptive_timeout((*self.walls, *more), self.configured, self.multiple, self.floor)


def _policy(timeout) -> TimeoutPolicy:
    return timeout if isinstance(timeout, TimeoutPolicy) else TimeoutPolicy(float(timeout))


# ----------------------------------------------------------------------------- statistics
def window_statistics(samples: np.ndarray, psi_rad: np.ndarray | None, orders=HARMONIC_ORDERS):
    """Mean, half-window means and harmonic coefficients of sampled signals.

    Parameters
    ----------
    samples : ndarray, shape (n_samples, n_signals)
        Values at the ends of the averaging steps (equally spaced in azimuth, whole
        revolutions, ``n_samples`` even).
    psi_rad : ndarray, shape (n_samples,) or None
        Azimuth of blade 1 at each sample [rad]; None: no harmonics (standstill).
    orders : sequence of int
        Harmonic orders n.

    Returns
    -------
    mean : ndarray, shape (n_signals,)
    halves : ndarray, shape (2, n_signals)
    harmonics : ndarray of complex, shape (n_signals, n_orders)
        c_n = (2/N) Σ_k x_k exp(−i n ψ_k).
    """
    x = np.asarray(samples, float)
    n = x.shape[0]
    mean = x.mean(axis=0)
    halves = np.stack([x[: n // 2].mean(axis=0), x[n // 2:].mean(axis=0)])
    if psi_rad is None:
        harmonics = np.full((x.shape[1], len(orders)), np.nan + 0j)
    else:
        basis = np.exp(-1j * np.outer(np.asarray(psi_rad, float), np.asarray(orders, float)))
        harmonics = (2.0 / n) * (x.T @ basis)
    return mean, halves, harmonics


def convergence_failures(mean: np.ndarray, halves: np.ndarray, samples: np.ndarray, rtol: float,
                         checked, names) -> list[str]:
    """Signals whose half-window means differ by more than ``rtol`` × max(|mean|, std)."""
    out = []
    std = samples.std(axis=0)
    for i in checked:
        ref = max(abs(mean[i]), std[i], 1e-300)
        diff = abs(halves[1, i] - halves[0, i])
        if not diff <= rtol * ref:
            out.append(f"{names[i]} (halves differ by {diff / ref:.2e} relative, allowed {rtol:g})")
    return out


# ----------------------------------------------------------------------------- in-process driver
class Simulator:
    """One FMU instance in this process, driven through a :class:`SimulationPlan`.

    The instance is created on first use and reused: ``reset`` before every cold run; after
    an error the instance is freed and created again (a vendor FMU may be unusable after
    an error). After a fatal status ``fatal`` is set: FMI allows no further call of any
    instance, so a worker process ends (:func:`child_main`); in process, the instance is
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

    def _outcome(self, raw, times, counters, rotor_speed, steps, t0_wall, check: bool = True) -> RunOutcome:
        p = self.plan
        sig = p.signals
        x = np.empty((raw.shape[0], len(sig)))
        for i, s in enumerate(sig):
            y = s.sign * (s.scale * raw[:, s.index] + s.offset)
            x[:, i] = np.mod(y, s.wrap) if s.wrap else y
        if not rotor_speed > 0:
            psi = None                                    # standstill: no harmonics
        elif p.azimuth is not None:
            psi = np.radians(x[:, p.azimuth])
        else:                                             # no azimuth output: from the rotor speed, 0 at t = 0
            psi = 2.0 * np.pi * rotor_speed / 60.0 * times
        mean, halves, harm = window_statistics(x, psi)
        names = [s.name for s in sig]
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
            _, _, _, t = self._window(t, h, n_settle, 0)
            if keep_state:
                state, t_state = self.get_state(), t
            raw, times, counters, t = self._window(t, h, 0, n_average)
        except Exception as exc:  # noqa: BLE001 - an FMU error is this run's status
            return self._failure(exc, "simulation failed", t0_wall), None, 0.0
        outcome = self._outcome(raw, times, counters, task.rotor_speed, n_settle + n_average, t0_wall)
        outcome.instantiation = self.last_instantiation if self.instantiations != created else 0.0
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
        return self._outcome(raw, times, counters, task.rotor_speed, n_settle + n_average, t0_wall, check)

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
        if task.base_state is None:
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


# ----------------------------------------------------------------------------- child process
def _write_message(fd: int, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    payload = struct.pack("<Q", len(data)) + data
    view = memoryview(payload)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exact(fd: int, n: int) -> bytes | None:
    chunks, got = [], 0
    while got < n:
        b = os.read(fd, n - got)
        if not b:
            return None
        chunks.append(b)
        got += len(b)
    return b"".join(chunks)


def _read_message(fd: int):
    head = _read_exact(fd, 8)
    if head is None:
        return None
    body = _read_exact(fd, struct.unpack("<Q", head)[0])
    return None if body is None else pickle.loads(body)


def child_main() -> int:
    """Entry point of a worker process: read requests from stdin, answer on the original stdout.

    File descriptor 1 is pointed at stderr first, so that an FMU printing to stdout cannot
    corrupt the message stream. After a fatal FMI status the process answers ``("fatal",)``
    and exits at once, without any further FMI call (the supervisor starts a new one).
    """
    out_fd = os.dup(1)
    os.dup2(2, 1)
    in_fd = 0
    sim = None
    while True:
        msg = _read_message(in_fd)
        if msg is None or msg[0] == "close":
            if sim is not None:
                sim.close()
            return 0
        kind, payload = msg
        if kind == "plan":
            if sim is not None:
                sim.close()
            sim = Simulator(payload)
            sim.notify = lambda m: _write_message(out_fd, m)
            _write_message(out_fd, ("ready", os.getpid()))
        elif kind == "probe":
            _child_probe(sim, payload, out_fd)
        elif kind == "point":
            _child_point(sim, payload, out_fd)


def _child_fatal(out_fd: int) -> None:
    _write_message(out_fd, ("fatal",))
    os._exit(0)


def _child_probe(sim: Simulator, reads, out_fd: int) -> None:
    try:
        _write_message(out_fd, ("probe", sim.probe(reads)))
    except Exception as exc:  # noqa: BLE001
        _write_message(out_fd, ("error", f"{type(exc).__name__}: {exc}"))
        if getattr(exc, "status", None) == FMI_FATAL:
            _child_fatal(out_fd)


def _child_point(sim: Simulator, task: PointTask, out_fd: int) -> None:
    try:
        for item in sim.runs(task):
            _write_message(out_fd, item)
            if sim.fatal:
                _child_fatal(out_fd)
    except Exception as exc:  # noqa: BLE001 - reported to the supervisor
        _write_message(out_fd, ("error", f"{type(exc).__name__}: {exc}"))
    _write_message(out_fd, ("done",))


# ----------------------------------------------------------------------------- supervisor
def _signal_name(returncode: int | None) -> str:
    if returncode is None:
        return "still running"
    if returncode < 0:
        try:
            return f"killed by signal {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exit status {returncode}"


# The child imports this module by its name (not as __main__), so pickled classes resolve alike;
# the package calib.models is registered without running its __init__ (which imports the
# calibration stack, scipy.stats included: 2 s per worker start for nothing the child uses).
_CHILD_COMMAND = (
    "import sys, types, calib, os\n"
    "pkg = types.ModuleType('calib.models')\n"
    "pkg.__path__ = [os.path.join(os.path.dirname(calib.__file__), 'models')]\n"
    "sys.modules['calib.models'] = pkg\n"
    "from calib.models.fmu_worker import child_main\n"
    "sys.exit(child_main())\n")


class WorkerProcess:
    """A child process that simulates; rebuilt after a crash, a hang or a fatal status.

    Parameters
    ----------
    plan : SimulationPlan
    timeout : float or TimeoutPolicy
        Longest wall time of one simulation [s], or the policy of an adaptive one: a run
        taking longer is killed and recorded with status ``TIMEOUT``. With a policy the
        timeout in force (:attr:`timeout`) follows :func:`adaptive_timeout` over the policy's
        wall times and those this worker measured since it got the policy.
    start_timeout : float, optional
        Longest wall time for the child to start and load the plan, and for an FMU
        instance to be created [s] (default: the policy's, 60 s).
    """

    def __init__(self, plan: SimulationPlan, timeout=DEFAULT_TIMEOUT, start_timeout: float | None = None):
        self.plan = plan
        policy = _policy(timeout)
        if start_timeout is not None:
            policy = replace(policy, start_timeout=float(start_timeout))
        self.policy = policy
        self._walls: list[float] = []
        self.proc: subprocess.Popen | None = None
        self.restarts = 0
        self.owner = os.getpid()

    @property
    def timeout(self) -> float:
        """The simulation timeout in force [s]."""
        return self.policy.timeout(self._walls)

    @property
    def start_timeout(self) -> float:
        return self.policy.start_timeout

    def set_policy(self, policy) -> None:
        """Use ``policy`` (a float: a fixed timeout); this worker's own measurements are
        dropped when it changes (the new policy holds them, measured by the planner)."""
        policy = _policy(policy)
        if policy != self.policy:
            self.policy = policy
            self._walls = []

    def _measured(self, outcome: RunOutcome, task: PointTask) -> None:
        """Count a healthy base run (full window, from scratch) in the timeout rule."""
        if outcome.ok and task.start_state is None:
            self._walls.append(outcome.wall - outcome.instantiation)
            del self._walls[:-HEALTHY_WALLS_KEPT]

    def _start(self):
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        self.proc = subprocess.Popen([sys.executable, "-c", _CHILD_COMMAND], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=env, close_fds=True)
        _write_message(self.proc.stdin.fileno(), ("plan", self.plan))
        reply = self._receive(self.start_timeout)
        if not (isinstance(reply, tuple) and reply[0] == "ready"):
            why = reply if isinstance(reply, str) else _signal_name(self.proc.poll())
            self.kill()
            raise RuntimeError(f"FMU worker process did not start: {why}")

    def _ensure_started(self):
        if self.proc is None or self.proc.poll() is not None:
            self.kill()
            self._start()

    def _receive(self, timeout: float):
        """The next message, or "timeout" / "died" (strings)."""
        fd = self.proc.stdout.fileno()
        ready, _, _ = select.select([fd], [], [], timeout)
        if not ready:
            return "timeout"
        msg = _read_message(fd)
        if msg is None:
            self.proc.wait()
            return "died"
        return msg

    def _next(self):
        """The next message that is not an instantiation notice, or "timeout", "start-timeout"
        (the instance was not created within ``start_timeout``), "died". An instance being
        created is waited for up to ``start_timeout``; the run's timeout starts again after it."""
        limit, creating = self.timeout, False
        while True:
            msg = self._receive(limit)
            if isinstance(msg, tuple) and msg[0] in ("instantiating", "instantiated"):
                creating = msg[0] == "instantiating"
                limit = self.start_timeout if creating else self.timeout
                continue
            return "start-timeout" if msg == "timeout" and creating else msg

    def kill(self):
        if self.proc is not None:
            try:
                self.proc.kill()
            except ProcessLookupError:
                pass
            self.proc.wait()
            for stream in (self.proc.stdin, self.proc.stdout):
                try:
                    stream.close()
                except OSError:
                    pass
        self.proc = None

    def close(self):
        """Ask the child to free its instance and exit (killed after 5 s)."""
        if self.proc is not None and self.proc.poll() is None:
            try:
                _write_message(self.proc.stdin.fileno(), ("close", None))
                self.proc.wait(timeout=5)
            except (OSError, subprocess.TimeoutExpired):
                pass
        self.kill()

    def probe(self, reads) -> list:
        """:meth:`Simulator.probe` in the child (raises RuntimeError on any fault)."""
        self._ensure_started()
        _write_message(self.proc.stdin.fileno(), ("probe", reads))
        msg = self._next()
        if not (isinstance(msg, tuple) and msg[0] == "probe"):
            why = msg[1] if isinstance(msg, tuple) else msg
            self.kill()
            raise RuntimeError(f"probe failed: {why}")
        return msg[1]

    def run_point(self, task: PointTask) -> PointResult:
        """All runs of a point; a fault becomes the status of the run it hit, and the rest go on."""
        res = PointResult(task.index, None, [None] * len(task.perturbations))
        pending = task
        while pending is not None:
            self._ensure_started()
            _write_message(self.proc.stdin.fileno(), ("point", pending))
            fault = self._collect(pending, res)
            res.timeout = self.timeout
            pending = None if fault is None else self._after_fault(task, res, *fault)
        return res

    def _collect(self, pending: PointTask, res: PointResult):
        """Read the runs of ``pending`` into ``res`` until done; the fault met, as (status,
        message, kind), or None."""
        current = "base run" if pending.base_state is None else f"perturbed run {pending.skip + 1}"
        fault = None
        while True:
            timeout = self.timeout
            msg = self._next()
            if msg == "timeout":
                return (Status.TIMEOUT, f"{current} exceeded the timeout of {timeout:g} s; worker process killed "
                                        "and rebuilt", "timeout")
            if msg == "start-timeout":
                return (Status.TIMEOUT, f"creating the FMU instance for the {current} exceeded the start timeout of "
                                        f"{self.start_timeout:g} s; worker process killed and rebuilt", "start-timeout")
            if msg == "died":
                return (Status.SIMULATION_FAILED, f"the FMU process died during the {current} "
                                                  f"({_signal_name(self.proc.returncode)}); worker rebuilt", "crash")
            if msg[0] == "base":
                res.base, res.base_state = msg[1], msg[2]
                self._measured(msg[1], pending)
                current = "perturbed run 1"
            elif msg[0] == "run":
                res.perturbations[msg[1]] = msg[2]
                current = f"perturbed run {msg[1] + 2}"
            elif msg[0] == "fatal":
                return (None, "", "fatal")
            elif msg[0] == "error":
                fault = (Status.SIMULATION_FAILED, f"worker error during the {current}: {msg[1]}", "error")
            elif msg[0] == "done":
                return fault

    def _after_fault(self, task: PointTask, res: PointResult, status, message: str, kind: str):
        """Record a fault in ``res``; the task of the runs still to do, or None."""
        if kind in ("timeout", "start-timeout", "crash", "fatal"):
            self.kill()
            self.restarts += 1
            res.restarts += 1
        done = [k for k, r in enumerate(res.perturbations) if r is not None]
        last = max(done) if done else -1
        if kind == "fatal":                 # the run's own outcome arrived: say what follows
            hit = res.base if last < 0 else res.perturbations[last]
            hit.message = (hit.message.rstrip(".") + "; fatal status: no further FMI call allowed, worker process "
                           "replaced")
        else:
            failed = RunOutcome.failed(len(self.plan.signals), status, message, fault=kind)
            if res.base is None:
                res.base = failed
                return None
            last += 1
            if last >= len(task.perturbations):
                return None
            res.perturbations[last] = failed
        if last + 1 >= len(task.perturbations) or not res.base.ok:
            return None
        pending = replace(task, base_state=res.base_state, skip=last + 1)
        if res.base_state is None:      # no serialized state: cold perturbed runs
            pending = replace(pending, warm=False)
        return pending


# ----------------------------------------------------------------------------- per-process cache
_WORKERS: dict = {}


def worker_for(plan: SimulationPlan, isolate: bool = True, timeout=DEFAULT_TIMEOUT):
    """The worker of this process for ``plan`` (created once, reused by later tasks).

    ``timeout`` (float [s] or :class:`TimeoutPolicy`) is handed to the worker at every call:
    a changed timeout does not start another process.
    """
    key = (os.getpid(), plan.key, isolate)
    w = _WORKERS.get(key)
    if w is None:
        for k in [k for k in _WORKERS if k[0] != os.getpid()]:   # inherited through fork: not ours
            _WORKERS.pop(k)
        w = WorkerProcess(plan, timeout) if isolate else Simulator(plan)
        _WORKERS[key] = w
    elif isolate:
        w.set_policy(timeout)
    return w


def close_workers(plan_key: str | None = None) -> None:
    """Close this process's workers (of one plan, or all)."""
    for k in [k for k in _WORKERS if plan_key is None or k[1] == plan_key]:
        w = _WORKERS.pop(k)
        if k[0] == os.getpid():
            w.close()


def run_point(job) -> PointResult:
    """Executor task: ``job = (plan, task, isolate, timeout)`` -> :class:`PointResult`
    (``timeout``: float [s] or :class:`TimeoutPolicy`)."""
    plan, task, isolate, timeout = job
    return worker_for(plan, isolate, timeout).run_point(task)


import atexit  # noqa: E402

atexit.register(close_workers)

if __name__ == "__main__":
    sys.exit(child_main())
