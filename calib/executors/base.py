"""The executor interface and the serial executor."""

from __future__ import annotations

from typing import Callable, Iterable, Protocol, Sequence, runtime_checkable

Progress = Callable[[int, int], None]


@runtime_checkable
class Executor(Protocol):
    """Runs ``fn`` over ``tasks``; results in task order."""

    name: str
    workers: int

    def map(self, fn: Callable, tasks: Sequence, progress: Progress | None = None) -> list: ...

    def close(self) -> None: ...


class SerialExecutor:
    """Runs every task in this process, one after the other.

    Parameters
    ----------
    progress : callable(done, total), optional
        Default progress callback (a ``map`` call may pass its own).
    """

    name = "serial"
    workers = 1

    def __init__(self, progress: Progress | None = None):
        self.progress = progress

    def map(self, fn: Callable, tasks: Iterable, progress: Progress | None = None) -> list:
        tasks = list(tasks)
        report = progress or self.progress
        out = []
        for k, task in enumerate(tasks):
            out.append(fn(task))
            if report:
                report(k + 1, len(tasks))
        return out

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return "SerialExecutor()"
