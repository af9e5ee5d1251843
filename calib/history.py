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
the records (:class:`~calib.models.recorded_model.RecordedModel`, keyed on a hash of the model's
identity, the call kind, the parameter vector's bytes and the operating conditions' bytes)
retraces the killed run exactly, with no simulation repeated, and continues from where it
stopped. Resuming into a folder whose recorded inputs differ is refused (:func:`open_history`).

Read a history with :func:`read_events` and :func:`read_record` (or ``json`` and
``numpy.load`` directly).

This module holds the folder (:class:`History`, :func:`open_history`) and its reading; the
recorded model calls (:class:`~calib.models.recorded_model.RecordedModel`, :func:`~calib.models.recorded_model.recorded`) live in
:mod:`calib.models.recorded_model`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
from pathlib import Path

import numpy as np

from calib.calibration.result_io import jsonable as result_jsonable
from calib.errors import InputError

FORMAT = "calib.history/1"
HISTORY_DIR = "history"

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
        self.replayed = 0          # calls answered from a record of an earlier (killed) run
        self.repeated = 0          # calls this run had made already, answered from its own record
        self._this_run: set[str] = set()
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

    def recorded_by_this_run(self, key: str) -> bool:
        """Whether the record of ``key`` was written by this run (not read from an earlier one)."""
        return key in self._this_run

    def calls_sentence(self) -> str:
        """"N computed, M read back from FOLDER[, R repeated]": the model calls of the run."""
        text = f"{self.computed} computed, {self.replayed} read back from {self.folder}"
        if self.repeated:
            text += f", {self.repeated} repeated within this run (answered from its own record)"
        return text

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
            self._this_run.add(event["key"])
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
