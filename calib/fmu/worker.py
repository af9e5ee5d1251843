"""FMU simulations in worker processes: one instance per worker, faults survived.

Three layers, each usable alone, and the planner's record of faults:

- :class:`~calib.fmu.simulator.Simulator` drives one FMU instance in this process through fmpy: instantiate
  once, ``reset`` between runs, settle, average over whole revolutions, save / restore /
  serialize the FMU state, and turn what the FMU reports into a per-run status.
- :class:`WorkerProcess` runs a :class:`Simulator` in a child process (a new Python
  interpreter running :func:`calib.fmu.child.child_main`) and talks to it over pipes
  (:mod:`calib.fmu.pipe`). Every simulation has a timeout; an error status, a crash of the
  process (e.g. ``abort()`` in the FMU) or a hang
  becomes that run's status, the child is rebuilt (after a crash, a hang or a fatal
  status), and the runs still to do go on from the serialized settled state (so nothing
  computed before is lost). The timeout adapts (:func:`adaptive_timeout`) to the healthy
  runs measured by the planner (:class:`TimeoutPolicy`) and by the worker itself; creating
  the FMU instance is timed apart, against the start timeout.
- :func:`run_point` is what an executor maps over operating points: it gets a picklable
  :class:`SimulationPlan` and :class:`PointTask` (paths and values, never an instance) and
  uses the worker of the current process (one per plan, kept for later tasks).
- :class:`calib.fmu.faults.FaultLedger` lives with the model, where tasks are
  planned: it quarantines points that crashed or hung, so that later calls do not simulate
  them again, and keeps the healthy wall times that set the timeout.

Statistics of a run: :mod:`calib.fmu.windows`; plans, tasks and the timeout rule: :mod:`calib.fmu.plan`.
"""

from __future__ import annotations

import logging
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import replace

from calib.fmu.pipe import read_message, write_message
from calib.fmu.plan import (DEFAULT_TIMEOUT, HEALTHY_WALLS_KEPT, PointResult, PointTask, RunOutcome,
                            SimulationPlan, policy_of)
from calib.fmu.simulator import Simulator
from calib.types import Status

log = logging.getLogger(__name__)


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
        policy = policy_of(timeout)
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
        policy = policy_of(policy)
        if policy != self.policy:
            self.policy = policy
            self._walls = []

    def _measured(self, outcome: RunOutcome, task: PointTask) -> None:
        """Count a healthy base run (full window, from scratch) in the timeout rule."""
        if outcome.ok and task.start_state is None and not outcome.reused:
            self._walls.append(outcome.wall - outcome.instantiation)
            del self._walls[:-HEALTHY_WALLS_KEPT]

    def _start(self):
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        # ``-m``: the child imports calib's modules by their names (so pickled classes resolve alike); calib and
        # calib.fmu import nothing at package level, so the child loads fmpy and numpy, not the calibration stack
        self.proc = subprocess.Popen([sys.executable, "-m", "calib.fmu.child"], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, env=env, close_fds=True)
        write_message(self.proc.stdin.fileno(), ("plan", self.plan))
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
        msg = read_message(fd)
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
        """Ask the child to free its instance and exit (killed after 5 s). A child that ends by a
        signal while freeing its instance (the FMU's library aborting on a corrupted heap) is
        logged as a warning naming the signal: the results it returned before stand."""
        if self.proc is not None and self.proc.poll() is None:
            try:
                write_message(self.proc.stdin.fileno(), ("close", None))
                code = self.proc.wait(timeout=5)
                if code < 0:
                    log.warning("the FMU process %d ended with %s while freeing its instance of %s (the FMU's "
                                "library, at close; the results it returned before stand)", self.proc.pid,
                                signal.Signals(-code).name, self.plan.model_identifier)
            except (OSError, subprocess.TimeoutExpired, ValueError):
                pass
        self.kill()

    def probe(self, reads) -> list:
        """:meth:`Simulator.probe` in the child (raises RuntimeError on any fault)."""
        self._ensure_started()
        write_message(self.proc.stdin.fileno(), ("probe", reads))
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
            write_message(self.proc.stdin.fileno(), ("point", pending))
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
    (``timeout``: float [s] or :class:`TimeoutPolicy`), with the wall time spent on it as ``busy`` [s]."""
    t0 = time.perf_counter()
    plan, task, isolate, timeout = job
    result = worker_for(plan, isolate, timeout).run_point(task)
    result.busy = time.perf_counter() - t0
    return result


import atexit  # noqa: E402

atexit.register(close_workers)
