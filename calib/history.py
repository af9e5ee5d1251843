"""On-disk history of a run, and resuming a killed run from it.

A calibration (``calib run``) or a diagnosis (``calib diagnose``) keeps, in its output
folder::

    history/manifest.json     what ran: command, inputs and their SHA-256, calib version
    history/events.jsonl      one JSON object per line, appended as things happen
    history/records/KEY.npz   one model call's outputs (values, status, messages,
                              Jacobian G, extras, parameters, conditions)

Every model call (an evaluation or a Jacobian over a batch of operating points; for an
FMU, a chunk of points, so that a kill loses at most one chunk of simulations) and every
optimizer iteration is an event. A call's line is appended, flushed and fsynced only after
its ``.npz`` is complete under its final name (written through a temporary file and a
rename), so a line never points at a missing or truncated record; a kill during an append
leaves at most one incomplete last line, which is ignored (and cut) on resume.

Resume rests on determinism: the calibration and the diagnosis are deterministic
functions of their inputs, so running them again with every model call answered from
the records (:class:`RecordedModel`, keyed on a hash of the model's identity, the call
kind, the parameter vector's bytes and the operating conditions' bytes) retraces the
killed run exactly, with no simulation repeated, and continues from where it stopped.
Resuming into a folder whose recorded inputs differ is refused (:func:`open_history`).

Read a history with :func:`read_events` and :func:`read_record` (or ``json`` and
``numpy.load`` directly).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from pathlib import Path
from typing import Callable

import numpy as np

from calib.errors import InputError
from calib.result import _jsonable as result_jsonable
from calib.types import CONDITION_FIELDS, Evaluation, OperatingConditions

FORMAT = "calib.history/1"
HISTORY_DIR = "history"
#: Extras that describe the stations, not the points (kept whole when chunks are joined).
PER_STATION_EXTRAS = ("eta", "interior")

log = logging.getLogger("calib.history")


def _jsonable(x):
    """JSON types for events and manifests; any other object as its ``str``."""
    return result_jsonable(x, fallback=str)


def content_digest(obj) -> str:
    """SHA-256 of the content of numbers, arrays, strings and (nested) dataclasses.

    Dataclass fields declared with ``compare=False`` (e.g. a rotor's ``source`` path) are left
    out, so the digest says whether two objects hold the same data, wherever they came from.
    Used to record a rotor's geometry and polars in the manifest: a rotor file edited between
    a kill and ``--resume`` is then refused, even one reached indirectly (an OpenFAST deck's
    airfoil tables).
    """
    import dataclasses

    h = hashlib.sha256()

    def walk(x):
        if dataclasses.is_dataclass(x) and not isinstance(x, type):
            h.update(f"<{type(x).__name__}>".encode())
            for f in dataclasses.fields(x):
                if f.compare:
                    h.update(f.name.encode())
                    walk(getattr(x, f.name))
        elif isinstance(x, np.ndarray):
            h.update(f"{x.dtype.str}{x.shape}".encode())
            h.update(np.ascontiguousarray(x).tobytes() if x.dtype != object else repr(x.tolist()).encode())
        elif isinstance(x, dict):
            for k in sorted(x, key=str):
                h.update(str(k).encode())
                walk(x[k])
        elif isinstance(x, (list, tuple)):
            h.update(f"[{len(x)}".encode())
            for v in x:
                walk(v)
        else:
            h.update(repr(x).encode())
        h.update(b";")

    walk(obj)
    return h.hexdigest()


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _atomic_npz(path: Path, arrays: dict) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


class History:
    """The ``history/`` folder of one output folder (see the module notes).

    Use :func:`open_history` to create or resume one.

    Attributes
    ----------
    folder : Path
        ``OUT/history``.
    manifest : dict
        What ran (``manifest.json``).
    resumed : bool
        Whether this run resumes a killed one.
    """

    def __init__(self, folder: Path, manifest: dict, resumed: bool):
        self.folder = Path(folder)
        self.records = self.folder / "records"
        self.events_path = self.folder / "events.jsonl"
        self.manifest = manifest
        self.resumed = resumed
        self._index: dict[str, str] = {}
        self.computed = 0
        self.replayed = 0
        if resumed:
            self._load_index()

    # ------------------------------------------------------------------ reading
    def _load_index(self) -> None:
        events, good_bytes = _read_lines(self.events_path)
        size = self.events_path.stat().st_size if self.events_path.exists() else 0
        if good_bytes < size:       # a line cut by the kill: drop it before appending
            with open(self.events_path, "r+b") as fh:
                fh.truncate(good_bytes)
            log.info("history: dropped an incomplete last line of %s (%d bytes)", self.events_path,
                     size - good_bytes)
        for ev in events:
            rec = ev.get("record")
            if rec and (self.records / rec).is_file():
                self._index[ev["key"]] = rec

    def lookup(self, key: str) -> Path | None:
        """The record file of a call key, or None."""
        name = self._index.get(key)
        return None if name is None else self.records / name

    @property
    def n_records(self) -> int:
        return len(self._index)

    # ------------------------------------------------------------------ writing
    def append(self, event: dict, arrays: dict | None = None) -> None:
        """Append one event (and its record's arrays first, when given).

        Parameters
        ----------
        event : dict
            JSON-able (numpy values are converted); ``time`` [s since the epoch] is added.
        arrays : dict of str -> ndarray, optional
            Written to ``records/<event["key"]>.npz`` before the line is appended.
        """
        event = {"time": round(time.time(), 3), **event}
        if arrays is not None:
            name = f"{event['key']}.npz"
            self.records.mkdir(parents=True, exist_ok=True)
            _atomic_npz(self.records / name, arrays)
            event["record"] = name
            self._index[event["key"]] = name
        line = json.dumps(_jsonable(event), allow_nan=True) + "\n"
        # one write() on an O_APPEND descriptor: lines of processes sharing the file do not interleave
        fd = os.open(self.events_path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        try:
            os.write(fd, line.encode())
            os.fsync(fd)
        finally:
            os.close(fd)

    def event(self, kind: str, **fields) -> None:
        """Append an event without a record (``{"event": kind, ...}``)."""
        self.append({"event": kind, **fields})

    def __repr__(self) -> str:
        return f"History({str(self.folder)!r}, {self.n_records} records, resumed={self.resumed})"


def _read_lines(path: Path) -> tuple[list[dict], int]:
    """Complete JSON lines of ``path`` and the byte count they span."""
    if not path.exists():
        return [], 0
    raw = path.read_bytes()
    out, pos = [], 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            break
        try:
            out.append(json.loads(raw[pos:end]))
        except ValueError:
            break
        pos = end + 1
    return out, pos


def read_events(out_dir: str | Path) -> list[dict]:
    """The events of ``OUT/history/events.jsonl`` (an incomplete last line is left out)."""
    return _read_lines(Path(out_dir) / HISTORY_DIR / "events.jsonl")[0]


def read_record(out_dir: str | Path, event: dict) -> dict:
    """The arrays of one event's record (``OUT/history/records/<record>``)."""
    with np.load(Path(out_dir) / HISTORY_DIR / "records" / event["record"]) as z:
        return {k: z[k] for k in z.files}


def count_model_calls(events: list[dict], since_last_start: bool = False) -> dict:
    """How many model calls were computed and how many answered from the records.

    Parameters
    ----------
    events : list of dict
        From :func:`read_events`.
    since_last_start : bool
        Count only after the last ``start`` event (the last run or resume).

    Returns
    -------
    dict
        ``computed``, ``replayed`` (calls), ``computed_points`` (points simulated).
    """
    if since_last_start:
        starts = [k for k, e in enumerate(events) if e.get("event") == "start"]
        events = events[starts[-1]:] if starts else events
    calls = [e for e in events if e.get("event") in ("evaluate", "jacobian")]
    computed = [e for e in calls if not e.get("replayed")]
    return {"computed": len(computed), "replayed": len(calls) - len(computed),
            "computed_points": int(sum(e.get("n_points", 0) for e in computed))}


def open_history(out_dir: str | Path, manifest: dict, resume: bool) -> History:
    """Create ``OUT/history`` for a new run, or reopen it to resume a killed one.

    Parameters
    ----------
    out_dir : str or Path
        The run's output folder.
    manifest : dict
        ``command`` and ``inputs`` ({label: SHA-256 or value}) of this run; on resume they
        must equal the recorded ones.
    resume : bool
        Reopen (and check) an existing history instead of starting a new one. A new run
        into a folder that holds a history replaces it.

    Raises
    ------
    InputError
        Resuming where there is no history, or a history of another command or of other
        inputs (each changed input named, with both hashes).
    """
    out = Path(out_dir)
    folder = out / HISTORY_DIR
    mpath = folder / "manifest.json"
    manifest = _jsonable({"format": FORMAT, **manifest})
    if resume:
        if not mpath.is_file():
            raise InputError(f"nothing to resume: no {HISTORY_DIR}/manifest.json in {out} (was the run started with "
                             "this --out folder?)", str(out), field="--resume")
        try:
            old = json.loads(mpath.read_text())
        except ValueError:
            raise InputError("history manifest is not valid JSON", str(mpath)) from None
        if old.get("command") != manifest.get("command"):
            raise InputError(f"the history in {out} is of 'calib {old.get('command')}', not 'calib "
                             f"{manifest.get('command')}'", str(mpath), field="command")
        changed = []
        new_inputs, old_inputs = manifest.get("inputs", {}), old.get("inputs", {})
        for key in sorted(set(new_inputs) | set(old_inputs)):
            if new_inputs.get(key) != old_inputs.get(key):
                changed.append(f"{key} (recorded {_short(old_inputs.get(key))}, now {_short(new_inputs.get(key))})")
        if changed:
            raise InputError("cannot resume: the inputs changed since the run started: " + "; ".join(changed)
                             + "; start a new run with another --out folder", str(mpath), field="inputs")
        history = History(folder, old, resumed=True)
        log.debug("history: resuming %s (%d records)", folder, history.n_records)
        return history
    if folder.exists():
        log.info("history: a new run replaces the history in %s", folder)
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    from calib import __version__
    manifest = {**manifest, "calib_version": __version__, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    tmp = folder / ".manifest.json.tmp"
    tmp.write_text(json.dumps(manifest, indent=1))
    with open(tmp, "rb") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, mpath)
    _fsync_dir(folder)
    return History(folder, manifest, resumed=False)


def _short(value) -> str:
    if value is None:
        return "nothing"
    text = str(value)
    return text[:12] if len(text) == 64 else text


# ----------------------------------------------------------------------------- recorded model calls
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
    text = json.dumps(_jsonable(desc), sort_keys=True)
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
