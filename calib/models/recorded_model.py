"""Recorded model calls (:class:`RecordedModel`, :func:`recorded`): a forward model whose every
call is written to a run's :class:`~calib.history.History` and, on resume, answered from it bit
for bit, keyed on a hash of the model's identity, the call kind, the parameter vector's bytes
and the operating conditions' bytes (see :mod:`calib.history`).
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from calib.calibration.result_io import jsonable as result_jsonable
from calib.errors import InputError
from calib.types import CONDITION_FIELDS, Evaluation, OperatingConditions

if TYPE_CHECKING:
    from calib.history import History

#: Extras that describe the stations, not the points (kept whole when chunks are joined).
PER_STATION_EXTRAS = ("eta", "interior")

log = logging.getLogger("calib.history")      # the history's: its records and replays


def _identity(model, label: str) -> str:
    """Hash of what makes a model's outputs what they are (type, parameters, channels, spec)."""
    desc = {"label": label, "type": model.capabilities.name,
            "parameters": [(q.name, q.nominal, q.lower, q.upper, q.scale) for q in model.parameters],
            "channels": [c.name for c in model.channels]}
    if model.capabilities.rebuildable:
        try:
            desc["spec"] = model.spec()
        except InputError:
            pass
    text = json.dumps(result_jsonable(desc, fallback=str), sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def _conditions_bytes(conditions: OperatingConditions) -> bytes:
    return b"".join(np.ascontiguousarray(getattr(conditions, f), float).tobytes() for f in CONDITION_FIELDS)


def _join(parts: list[Evaluation], channels) -> Evaluation:
    if len(parts) == 1:
        return parts[0]
    extras = {}
    for k in parts[0].extras:
        if k in PER_STATION_EXTRAS:
            extras[k] = parts[0].extras[k]
        else:
            extras[k] = np.concatenate([np.asarray(p.extras[k]) for p in parts], axis=0)
    return Evaluation(np.concatenate([p.values for p in parts]), np.concatenate([p.status for p in parts]),
                      tuple(m for p in parts for m in p.messages), channels, extras)


class RecordedModel:
    """A ForwardModel whose calls are written to a :class:`History` and answered from it.

    ``evaluate`` and ``jacobian`` look up each call (or chunk of points) by a hash of
    (the model's identity, the call kind, ``p``'s bytes, the conditions' bytes); a stored
    call is read back bit for bit, any other is computed by the wrapped model and recorded.
    Everything else (``parameters``, ``channels``, ``capabilities`` and the calls they
    declare) is the wrapped model's, so the calibrator sees the same model.

    Parameters
    ----------
    model : ForwardModel
    history : History
    label : str
        Names the model in the events (e.g. the stage or the candidate); part of its identity.
    chunk_points : int, optional
        Compute and record calls in chunks of this many operating points (an FMU: a kill then
        loses at most one chunk of simulations). Default: whole calls.
    progress : callable(done, total, label), optional
        Called after each chunk with points done of the call.
    """

    def __init__(self, model, history: History, label: str, chunk_points: int | None = None,
                 progress: Callable | None = None):
        self._model = model
        self._history = history
        self._label = label
        self._chunk = chunk_points
        self._progress = progress
        self._id = _identity(model, label)
        self.n_computed = 0
        self.n_replayed = 0

    @property
    def wrapped(self):
        """The model behind the records."""
        return self._model

    @property
    def parameters(self):
        return self._model.parameters

    @property
    def channels(self):
        return self._model.channels

    # -- the wrapped model's declared capabilities and their calls ----------------------------
    @property
    def capabilities(self):
        """The wrapped model's (its name included, so results are the same with and without a history)."""
        return self._model.capabilities

    def correction_field(self):
        return self._model.correction_field()

    def field_jacobian(self, grid, p, conditions: OperatingConditions):
        """The wrapped model's projected field sensitivities (not recorded: they reuse its last
        Jacobian without a model call); None when it has none or its last Jacobian was not at ``p``
        and ``conditions`` (a chunked or replayed call)."""
        projected = getattr(self._model, "field_jacobian", None)
        return None if projected is None else projected(grid, p, conditions)

    def with_grid(self, grid):
        """The wrapped model on another grid (not recorded: it serves the uncertainty's fine grid)."""
        return self._model.with_grid(grid)

    def spec(self) -> dict:
        return self._model.spec()

    @property
    def rotor_radius(self):
        return self._model.rotor_radius

    def close(self) -> None:
        if self._model.capabilities.closes:
            self._model.close()

    def __getstate__(self):
        # a terminal display does not travel to another process
        return {**self.__dict__, "_progress": None}

    def _key(self, kind: str, p: np.ndarray, conditions: OperatingConditions) -> str:
        h = hashlib.sha256()
        h.update(self._id.encode())
        h.update(kind.encode())
        h.update(np.ascontiguousarray(p, float).tobytes())
        h.update(_conditions_bytes(conditions))
        return h.hexdigest()[:40]

    def _chunks(self, n: int) -> list[slice]:
        size = int(self._chunk) if self._chunk and 0 < self._chunk < n else max(n, 1)
        return [slice(a, min(a + size, n)) for a in range(0, n, size)] or [slice(0, 0)]

    def _call(self, kind: str, p, conditions: OperatingConditions):
        p = np.asarray(p, float)
        parts = []
        n = len(conditions)
        chunks = self._chunks(n)
        for sl in chunks:
            cond = conditions if len(chunks) == 1 else conditions.subset(sl)
            parts.append(self._one(kind, p, cond, f"{sl.start}:{sl.stop}/{n}"))
            if self._progress is not None and len(chunks) > 1:
                self._progress(sl.stop, n, f"{self._label}: {kind} (points)")
        evs = [e for e, _ in parts]
        ev = _join(evs, self._model.channels)
        if kind == "evaluate":
            return ev
        return ev, np.concatenate([G for _, G in parts], axis=0)

    def _one(self, kind: str, p, cond, where: str):
        key = self._key(kind, p, cond)
        path = self._history.lookup(key)
        if path is not None:
            try:
                out = _load_call(path, self._model.channels, kind)
            except (OSError, ValueError, KeyError) as exc:   # a damaged record is computed again
                log.warning("history: record %s unreadable (%s); computing the call again", path.name, exc)
            else:
                self.n_replayed += 1
                if self._history.recorded_by_this_run(key):
                    self._history.repeated += 1
                else:
                    self._history.replayed += 1
                self._history.event(kind, key=key, label=self._label, points=where, n_points=len(cond),
                                    replayed=True)
                return out
        t0 = time.perf_counter()
        if kind == "evaluate":
            ev, G = self._model.evaluate(p, cond), None
        else:
            ev, G = self._model.jacobian(p, cond)
        wall = time.perf_counter() - t0
        self.n_computed += 1
        self._history.computed += 1
        arrays = {"p": p, "values": ev.values, "status": ev.status,
                  "messages": np.array(list(ev.messages), dtype=str) if len(ev.messages) else np.zeros(0, "U1")}
        arrays.update({f"conditions__{f}": getattr(cond, f) for f in CONDITION_FIELDS})
        for k, v in ev.extras.items():
            arrays[f"extras__{k}"] = np.asarray(v)
        if G is not None:
            arrays["G"] = G
        self._history.append({"event": kind, "key": key, "label": self._label, "points": where,
                              "n_points": len(cond), "n_failed": ev.n_failed, "wall": round(wall, 4)}, arrays)
        log.debug("%s: %s of %d points (%s) in %.2f s", self._label, kind, len(cond), where, wall)
        return ev, G

    def evaluate(self, p, conditions: OperatingConditions) -> Evaluation:
        """The wrapped model's ``evaluate``, recorded (or read back)."""
        return self._call("evaluate", p, conditions)

    def jacobian(self, p, conditions: OperatingConditions):
        """The wrapped model's ``jacobian``, recorded (or read back)."""
        return self._call("jacobian", p, conditions)

    def __repr__(self) -> str:
        return f"RecordedModel({self._model!r}, label={self._label!r})"


def _load_call(path: Path, channels, kind: str):
    with np.load(path) as z:
        extras = {k[len("extras__"):]: z[k] for k in z.files if k.startswith("extras__")}
        ev = Evaluation(z["values"], z["status"], tuple(str(m) for m in z["messages"]), tuple(channels), extras)
        G = z["G"] if kind == "jacobian" else None
    return ev, G


def recorded(model, history: History | None, label: str, chunk_points: int | None = None,
             progress: Callable | None = None):
    """``model`` wrapped in a :class:`RecordedModel` (``model`` itself when ``history`` is None)."""
    if history is None:
        return model
    return RecordedModel(model, history, label, chunk_points, progress)
