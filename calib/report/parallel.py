"""Figures drawn side by side in forked worker processes.

Matplotlib spends its time in Python (artists, ticks, text layout), one core per process,
so the report's figures are split over a few forked workers: each inherits the result
and the plotting modules from the parent (nothing is pickled or imported again), draws
its share, writes each file atomically and reports the paths over a pipe. The parent only
collects and forwards progress, so the user sees each figure as it is done.

Forking is used only where it is safe: on platforms with ``os.fork`` and while the parent
runs no other thread (a thread holding a lock at the moment of the fork would leave that
lock held forever in the child). Otherwise, and for one worker, the figures are drawn in
the calling process.

Interrupts: Ctrl-C reaches the whole foreground process group, so each worker gets its
own ``KeyboardInterrupt``, its atomic writes remove their temporary files, and it exits;
the parent, on its ``KeyboardInterrupt`` (or any error), stops the workers with SIGTERM
(turned into ``SystemExit``, with the same clean-up), waits for them and re-raises. A
figure a worker could not draw is drawn again in the parent, which raises the real error.
"""

from __future__ import annotations

import json
import os
import selectors
import signal
import sys
import threading
import time
import traceback
from typing import Callable

MAX_WORKERS = 4


def fork_available() -> bool:
    """Whether figures may be drawn in forked workers (``os.fork`` exists, no other thread runs)."""
    return hasattr(os, "fork") and threading.active_count() == 1


def available_cores() -> int:
    """Cores this process may run on."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def default_workers(n_tasks: int) -> int:
    """Workers for ``n_tasks`` figures: one per available core, at most ``MAX_WORKERS``."""
    return max(1, min(available_cores(), n_tasks, MAX_WORKERS))


def partition(costs: dict[str, float], n_groups: int) -> list[list[str]]:
    """Split tasks into ``n_groups`` of similar total cost (longest first onto the lightest group).

    Parameters
    ----------
    costs : dict
        Task name -> estimated cost (any unit).
    n_groups : int

    Returns
    -------
    list of list of str
        Non-empty groups; within a group, tasks keep the order of ``costs``.
    """
    groups: list[list[str]] = [[] for _ in range(max(1, n_groups))]
    load = [0.0] * len(groups)
    for name in sorted(costs, key=lambda k: -costs[k]):
        k = load.index(min(load))
        groups[k].append(name)
        load[k] += costs[name]
    order = list(costs)
    return [sorted(g, key=order.index) for g in groups if g]


def _worker(group: list[str], render: Callable[[str], object], write_fd: int) -> None:
    """Body of a forked worker: draw ``group``, report each result as one JSON line; never returns.

    SIGINT and SIGTERM stop the worker. Their exception can reach it as another error
    (matplotlib's C++ converters report a failing Python callback as ``ValueError``), so
    the handlers also set a flag that any exception, and each new figure, is checked
    against. Only the first signal raises: Ctrl-C reaches the worker and then the parent's
    SIGTERM follows, and a second exception raised while the first unwinds (in a finalizer
    or the unraisable-exception hook) would print a traceback. The stop exception itself,
    should it land in a finalizer, is not reported either: the worker is stopping anyway.
    """
    code = 1
    stop = []

    def on_signal(signum, frame):
        stop.append(signum)
        if len(stop) == 1:
            raise KeyboardInterrupt if signum == signal.SIGINT else SystemExit(128 + signum)

    default_hook = sys.unraisablehook

    def quiet_when_stopping(unraisable):
        if not (stop and isinstance(unraisable.exc_value, (KeyboardInterrupt, SystemExit))):
            default_hook(unraisable)

    try:
        sys.unraisablehook = quiet_when_stopping
        signal.signal(signal.SIGTERM, on_signal)
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, on_signal)
        for name in group:
            if stop:
                raise SystemExit(128 + stop[0])
            t0 = time.perf_counter()
            try:
                message = {"name": name, "value": render(name), "seconds": time.perf_counter() - t0}
            except Exception:  # noqa: BLE001 - reported to the parent, which draws it again
                if stop:
                    raise
                message = {"name": name, "error": traceback.format_exc()}
            os.write(write_fd, (json.dumps(message) + "\n").encode())
        code = 0
    except BaseException:  # noqa: BLE001 - KeyboardInterrupt / SystemExit: files already cleaned up
        code = 1
    finally:
        os._exit(code)


def run_forked(costs: dict[str, float], render: Callable[[str], object], n_workers: int,
               on_done: Callable[[str, object, float], None] | None = None) -> dict[str, object]:
    """Run ``render(name)`` for every task in forked workers.

    Parameters
    ----------
    costs : dict
        Task name -> estimated cost, used to balance the workers.
    render : callable
        ``render(name) -> value``; the value must be JSON-serializable (e.g. paths as str).
    n_workers : int
    on_done : callable, optional
        ``on_done(name, value, seconds)`` in the parent as each task finishes.

    Returns
    -------
    dict
        Task name -> value. Tasks a worker failed on (or never reported) are run again in
        the parent, so their exceptions propagate from here.
    """
    groups = partition(costs, n_workers)
    children: dict[int, int] = {}          # read fd -> pid, of the workers still running
    results: dict[str, object] = {}
    retry: list[str] = []
    try:
        _start_workers(groups, render, children)
        _collect(children, results, retry, on_done)
    except BaseException:
        _stop_workers(children)
        raise
    retry += [name for name in costs if name not in results and name not in retry]
    for name in [n for n in costs if n in retry]:
        t0 = time.perf_counter()
        results[name] = render(name)
        if on_done:
            on_done(name, results[name], time.perf_counter() - t0)
    return {name: results[name] for name in costs}


def _start_workers(groups: list[list[str]], render: Callable[[str], object], children: dict[int, int]) -> None:
    """Fork one worker per group, each writing to its own pipe (:func:`_worker`).

    Parameters
    ----------
    groups : list of list of str
        The tasks of each worker (:func:`partition`).
    render : callable
        As :func:`run_forked`.
    children : dict
        Filled as the workers start: read end of the worker's pipe -> its pid (so that the
        workers started before a failure can be stopped).
    """
    for group in groups:
        read_fd, write_fd = os.pipe()
        pid = os.fork()
        if pid == 0:                   # the child never leaves this block
            try:
                os.close(read_fd)
                for fd in children:
                    os.close(fd)
                _worker(group, render, write_fd)
            finally:
                os._exit(1)
        os.close(write_fd)
        children[read_fd] = pid


def _collect(children: dict[int, int], results: dict[str, object], retry: list[str],
             on_done: Callable[[str, object, float], None] | None) -> None:
    """Read the workers' JSON lines until every pipe is closed, reaping each worker as it ends.

    Parameters
    ----------
    children : dict
        Read end of each worker's pipe -> its pid; a worker is removed once reaped.
    results : dict
        Filled: task name -> value.
    retry : list of str
        Appended to: the tasks a worker reported an error for.
    on_done : callable or None
        As :func:`run_forked`, called as each result arrives.
    """
    selector = selectors.DefaultSelector()
    pending = {fd: b"" for fd in children}
    for fd in children:
        selector.register(fd, selectors.EVENT_READ)
    while pending:
        for key, _ in selector.select():
            fd = key.fd
            data = os.read(fd, 65536)
            if not data:
                selector.unregister(fd)
                os.close(fd)
                del pending[fd]
                os.waitpid(children.pop(fd), 0)
                continue
            *lines, pending[fd] = (pending[fd] + data).split(b"\n")
            for line in lines:
                message = json.loads(line)
                if "error" in message:
                    retry.append(message["name"])
                    continue
                results[message["name"]] = message["value"]
                if on_done:
                    on_done(message["name"], message["value"], message["seconds"])
    selector.close()


def _stop_workers(children: dict[int, int]) -> None:
    """Stop the workers still running with SIGTERM, wait for them and close their pipes.

    Parameters
    ----------
    children : dict
        Read end of each worker's pipe -> its pid.
    """
    for fd, pid in children.items():
        try:
            os.kill(pid, signal.SIGTERM)
        except ProcessLookupError:
            pass
    for fd, pid in children.items():
        os.waitpid(pid, 0)
        os.close(fd)
