"""The worker process itself: one :class:`~calib.fmu.simulator.Simulator` answering requests on pipes.

A :class:`calib.fmu.worker.WorkerProcess` starts a new Python interpreter as
``python -m calib.fmu.child`` and talks to it in the messages of :mod:`calib.fmu.pipe`: the
requests ``("plan", plan)`` (answered ``("ready", pid)``), ``("probe", reads)``, ``("point", task)``
and ``("close", None)``; the answers are the runs of a point as the simulator yields them, then
``("done",)``, or ``("error", text)``, or ``("fatal",)`` after which the process exits at once.
The module imports fmpy and numpy through the simulator, not the calibration stack.
"""

from __future__ import annotations

import os
import sys

from calib.fmu.pipe import read_message, write_message
from calib.fmu.plan import FMI_FATAL, PointTask
from calib.fmu.simulator import Simulator


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
        msg = read_message(in_fd)
        if msg is None or msg[0] == "close":
            if sim is not None:
                sim.close()
            _leave()
        kind, payload = msg
        if kind == "plan":
            if sim is not None:
                sim.close()
            sim = Simulator(payload)
            sim.notify = lambda m: write_message(out_fd, m)
            write_message(out_fd, ("ready", os.getpid()))
        elif kind == "probe":
            _child_probe(sim, payload, out_fd)
        elif kind == "point":
            _child_point(sim, payload, out_fd)


def _leave() -> None:
    """End the child at once after its instance is freed: no interpreter finalization and no exit
    handlers or static destructors of the FMU's shared library (or of an interpreter it embeds,
    as PythonFMU's do) run in a process that loaded a vendor binary. Those ran at exit, after the
    instance was freed, and are where a heap corrupted by the library shows itself ("corrupted
    double-linked list", "double free"); nothing is lost by skipping them: every answer has been
    written, and the supervisor reads the exit status."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(0)


def _child_fatal(out_fd: int) -> None:
    write_message(out_fd, ("fatal",))
    os._exit(0)


def _child_probe(sim: Simulator, reads, out_fd: int) -> None:
    try:
        write_message(out_fd, ("probe", sim.probe(reads)))
    except Exception as exc:  # noqa: BLE001
        write_message(out_fd, ("error", f"{type(exc).__name__}: {exc}"))
        if getattr(exc, "status", None) == FMI_FATAL:
            _child_fatal(out_fd)


def _child_point(sim: Simulator, task: PointTask, out_fd: int) -> None:
    try:
        for item in sim.runs(task):
            write_message(out_fd, item)
            if sim.fatal:
                _child_fatal(out_fd)
    except Exception as exc:  # noqa: BLE001 - reported to the supervisor
        write_message(out_fd, ("error", f"{type(exc).__name__}: {exc}"))
    write_message(out_fd, ("done",))


if __name__ == "__main__":
    sys.exit(child_main())
