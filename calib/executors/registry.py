"""Executors by name."""

from __future__ import annotations

from calib.errors import InputError
from calib.executors.base import SerialExecutor
from calib.executors.dask_executor import DaskExecutor
from calib.executors.process import ProcessExecutor

#: Executor kind -> class.
EXECUTORS = {"serial": SerialExecutor, "process": ProcessExecutor, "dask": DaskExecutor}


def get_executor(kind: str = "serial", workers: int | None = None, address: str | None = None,
                 progress=None, source: str = "executor"):
    """Build an executor by name.

    Parameters
    ----------
    kind : {"serial", "process", "dask"}
    workers : int, optional
        Processes (``process``, ``dask`` local cluster).
    address : str, optional
        Scheduler address (``dask`` only).
    progress : callable(done, total), optional
    source : str
        Where the request came from (named in errors).
    """
    if kind not in EXECUTORS:
        raise InputError(f"unknown executor kind {kind!r}; valid: {', '.join(EXECUTORS)}", source, field="kind")
    if kind == "serial":
        if address is not None:
            raise InputError("'address' applies to kind = \"dask\" only", source, field="address")
        return SerialExecutor(progress)
    if kind == "process":
        if address is not None:
            raise InputError("'address' applies to kind = \"dask\" only", source, field="address")
        return ProcessExecutor(workers, progress)
    return DaskExecutor(address, workers, progress)
