"""Dask distributed behind the executor interface."""

from __future__ import annotations

from typing import Callable, Iterable

from calib.errors import InputError
from calib.executors.base import Progress


class DaskExecutor:
    """Tasks on a Dask cluster (``dask.distributed``).

    Without ``address`` a ``LocalCluster`` of ``workers`` single-threaded worker processes
    is started on the first ``map`` (and closed by :meth:`close`); with ``address``
    (e.g. ``"tcp://scheduler:8786"``) the executor joins that cluster's scheduler and
    leaves it running. Tasks are submitted with ``pure=False`` (every call runs).

    Parameters
    ----------
    address : str, optional
        Scheduler address of an existing cluster.
    workers : int, optional
        Worker processes of the local cluster (default 2; ignored with ``address``).
    progress : callable(done, total), optional
    """

    name = "dask"

    def __init__(self, address: str | None = None, workers: int | None = None, progress: Progress | None = None):
        try:
            import dask.distributed  # noqa: F401
        except ImportError as exc:  # pragma: no cover - a core dependency
            raise InputError(f"the dask executor needs dask.distributed ({exc}); install with "
                             "pip install 'dask[distributed]'", "DaskExecutor", field="kind") from None
        if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
            raise InputError(f"workers must be an integer >= 1, got {workers!r}", "DaskExecutor", field="workers")
        self.address = address
        self.workers = workers or 2
        self.progress = progress
        self._client = None
        self._cluster = None

    @property
    def client(self):
        """The ``dask.distributed.Client`` (created on first use)."""
        if self._client is None:
            from dask.distributed import Client, LocalCluster

            if self.address:
                self._client = Client(self.address)
                self.workers = max(len(self._client.scheduler_info().get("workers", {})), 1)
            else:
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1, processes=True,
                                             dashboard_address=None)
                self._client = Client(self._cluster)
        return self._client

    def map(self, fn: Callable, tasks: Iterable, progress: Progress | None = None) -> list:
        from dask.distributed import as_completed

        tasks = list(tasks)
        if not tasks:
            return []
        report = progress or self.progress
        client = self.client
        futures = client.map(fn, tasks, pure=False)
        index = {f.key: k for k, f in enumerate(futures)}
        out = [None] * len(tasks)
        for done, fut in enumerate(as_completed(futures), start=1):
            out[index[fut.key]] = fut.result()
            if report:
                report(done, len(tasks))
        return out

    def close(self) -> None:
        if self._client is not None:
            if self._cluster is not None:
                # A local cluster's workers may still send a heartbeat while the scheduler closes;
                # distributed logs that race as an ERROR with a traceback (dask/distributed#7192).
                # Every result has been collected by now, so the workers keep quiet from here on.
                try:
                    self._client.run(_quiet_shutdown)
                except Exception:  # noqa: BLE001 - a worker already gone needs no quieting
                    pass
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __repr__(self) -> str:
        return f"DaskExecutor(address={self.address!r}, workers={self.workers})"


def _quiet_shutdown() -> None:
    """Raise the log level of a closing worker's own loggers (runs on each worker)."""
    import logging

    for name in ("distributed.worker", "distributed.nanny", "distributed.core", "distributed.comm"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
