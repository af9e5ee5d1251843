"""Executors: run one function over many tasks, serially, on local processes or on Dask.

Every executor has the same small interface (pyPESTO's engine pattern)::

    results = executor.map(fn, tasks, progress=None)

``fn`` must be a module-level function and every task picklable (the process pool and
Dask send them to other processes); results come back in task order; ``progress(done,
total)`` is called as tasks finish. The result of a task does not depend on which
executor or worker ran it, so the choice changes only the wall time.

Registry by name (:data:`EXECUTORS`): ``serial``, ``process`` (a local
``concurrent.futures`` process pool), ``dask`` (``dask.distributed``: a ``LocalCluster``
by default, or an existing scheduler at ``address``). :func:`get_executor` builds one.
"""

from calib.executors.base import Executor, SerialExecutor
from calib.executors.dask_executor import DaskExecutor
from calib.executors.process import ProcessExecutor
from calib.executors.registry import EXECUTORS, get_executor

__all__ = ["EXECUTORS", "DaskExecutor", "Executor", "ProcessExecutor", "SerialExecutor", "get_executor"]
