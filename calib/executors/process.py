"""A local process pool behind the executor interface."""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Callable, Iterable

from calib.errors import InputError
from calib.executors.base import Progress


def _exit_with_parent(parent_pid: int, period: float = 1.0) -> None:
    """Pool initializer: end this worker once the process that started the pool is gone.

    A run killed with SIGKILL never shuts its pool down, and a worker waiting for its next task
    would wait for ever (with the FMU processes it started); a daemon thread polls the parent
    and leaves with ``os._exit``, which closes the worker's pipes so its FMU processes end too.
    """

    def watch():
        while os.getppid() == parent_pid:
            time.sleep(period)
        os._exit(1)

    threading.Thread(target=watch, name="calib-exit-with-parent", daemon=True).start()


class ProcessExecutor:
    """Tasks on ``workers`` local processes (``concurrent.futures``, spawn start method).

    The pool starts on the first ``map`` and is kept for later calls, so a worker that set
    something up for a task (an FMU instance) reuses it for the next one. Processes are
    started with *spawn*: no state of this process (open libraries, threads) is inherited.
    Workers end by themselves when this process is killed (:func:`_exit_with_parent`).

    Parameters
    ----------
    workers : int, optional
        Number of processes (default: the CPU count).
    progress : callable(done, total), optional
    """

    name = "process"

    def __init__(self, workers: int | None = None, progress: Progress | None = None):
        workers = (os.cpu_count() or 1) if workers is None else workers
        if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
            raise InputError(f"workers must be an integer >= 1, got {workers!r}", "ProcessExecutor", field="workers")
        self.workers = workers
        self.progress = progress
        self._pool: ProcessPoolExecutor | None = None

    def _get_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(max_workers=self.workers,
                                             mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_exit_with_parent, initargs=(os.getpid(),))
        return self._pool

    def map(self, fn: Callable, tasks: Iterable, progress: Progress | None = None) -> list:
        tasks = list(tasks)
        report = progress or self.progress
        pool = self._get_pool()
        futures = {pool.submit(fn, t): k for k, t in enumerate(tasks)}
        out = [None] * len(tasks)
        for done, fut in enumerate(as_completed(futures), start=1):
            out[futures[fut]] = fut.result()
            if report:
                report(done, len(tasks))
        return out

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    def __repr__(self) -> str:
        return f"ProcessExecutor(workers={self.workers})"
