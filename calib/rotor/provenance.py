"""Provenance of the files a rotor is read from, and finding and checking them again.

- :func:`absolute_table`: the ``[rotor]`` table with absolute paths, as a result records it;
- :func:`file_provenance`: every file read, with its SHA-256 and its path relative to the
  workflow's folder;
- :func:`recorded_rotor_files`: what a result records (the provenance taken when read, or
  the files the table names, hashed now);
- the checks :func:`calib.rotor.sources.rotor_from_recorded_files` makes before and after it
  rebuilds a recorded rotor: each file located (at its recorded path, else in the result's
  folder) and compared with its recorded SHA-256.

Every error is an :class:`~calib.errors.InputError` naming the file and the key.
"""

from __future__ import annotations

import os
from pathlib import Path

from calib.errors import InputError
from calib.measurements import sha256_of

FILE_KEYS = ("openfast", "aerodyn", "aerodyn_blade", "windio")


def absolute_table(table: dict, base_dir) -> dict:
    """The ``[rotor]`` table with its file paths absolute and resolved (relative ones against
    ``base_dir``), the form a result records."""
    out = dict(table)
    base = Path(base_dir) if base_dir is not None else Path()
    for key in FILE_KEYS:
        if isinstance(out.get(key), str):
            out[key] = str((base / out[key]).resolve())
    if isinstance(out.get("airfoils"), list):
        out["airfoils"] = [str((base / a).resolve()) if isinstance(a, str) else a for a in out["airfoils"]]
    return out


def file_provenance(files, base_dir) -> dict:
    """Provenance of the files a rotor was read from (:attr:`~calib.rotor.sources.RotorSource.files`), for a result.

    Parameters
    ----------
    files : sequence of path
        Every file read, in reading order (an OpenFAST deck's ElastoDyn, AeroDyn, blade and
        airfoil files too).
    base_dir : str or Path or None
        The workflow's folder, that relative paths are given against.

    Returns
    -------
    dict
        ``{"workflow_dir", "all_files_read": True, "files": [{"path", "relative", "sha256"}, ...]}``:
        absolute path, path relative to ``base_dir`` and SHA-256 of each file.
    """
    wdir = None if base_dir is None else str(Path(base_dir).resolve())
    out = []
    for f in files:
        path = str(Path(f).resolve())
        try:
            rel = os.path.relpath(path, wdir) if wdir is not None else None
        except ValueError:          # another drive (Windows)
            rel = None
        out.append({"path": path, "relative": rel, "sha256": sha256_of(path) if Path(path).is_file() else None})
    return {"workflow_dir": wdir, "all_files_read": True, "files": out}


def _named_files(table: dict) -> list[tuple[str, str]]:
    """(key, path) of the files a table names itself, in table order."""
    out = [(f"rotor.{k}", table[k]) for k in FILE_KEYS if isinstance(table.get(k), str)]
    if isinstance(table.get("airfoils"), list):
        out += [(f"rotor.airfoils[{i}]", a) for i, a in enumerate(table["airfoils"]) if isinstance(a, str)]
    return out


def recorded_rotor_files(table: dict | None, read: dict | None = None) -> dict | None:
    """Provenance of the files behind a rotor table, for a result to record.

    Parameters
    ----------
    table : dict or None
        A ``[rotor]`` table with absolute paths (as :func:`absolute_table` gives it).
    read : dict, optional
        The provenance taken when the rotor was read (:func:`file_provenance`): every file
        read, hashed then, with paths relative to the workflow's folder.

    Returns
    -------
    dict or None
        None for an embedded rotor (no files); ``read`` when given; otherwise the files the
        table names, hashed now (``sha256`` None for one that is missing), with
        ``relative`` and ``workflow_dir`` None and ``all_files_read`` false.
    """
    if not isinstance(table, dict):
        return None
    named = _named_files(table)
    if not named:
        return None
    if read is not None:
        return read
    files = []
    for _, value in named:
        path = Path(value).expanduser().resolve()
        files.append({"path": str(path), "relative": None, "sha256": sha256_of(path) if path.is_file() else None})
    return {"workflow_dir": None, "all_files_read": False, "files": files}


def _changed(path, recorded: str, now: str, source: str, key: str) -> InputError:
    return InputError(f"rotor file {path} changed since the run (SHA-256 {recorded[:12]}... recorded, {now[:12]}... "
                      "now); restore the file the run read, or run the calibration again", source, None, key)


def records_by_path(provenance: dict | None) -> dict[str, dict]:
    """The recorded files of ``provenance`` (:func:`recorded_rotor_files`) by their absolute path.

    Parameters
    ----------
    provenance : dict or None
        The recorded provenance; None gives no records.

    Returns
    -------
    dict
        ``{path: record}``: each well-formed record ``{"path", "relative", "sha256"}`` by its absolute path.
    """
    records = {}
    for rec in (provenance or {}).get("files") or []:
        if isinstance(rec, dict) and isinstance(rec.get("path"), str):
            records[rec["path"]] = rec
    return records


def located_table(table: dict, records: dict[str, dict], rdir: Path | None, source: str) -> tuple[dict, bool]:
    """The recorded ``[rotor]`` table with each file it names found, and checked against its digest.

    Each file is looked for at its recorded absolute path, then in ``rdir`` under its recorded
    path relative to the workflow's folder, then in ``rdir`` under its name.

    Parameters
    ----------
    table : dict
        The recorded ``[rotor]`` table (absolute paths).
    records : dict
        The recorded files by path (:func:`records_by_path`).
    rdir : Path or None
        The result's folder, resolved.
    source : str
        Named in errors (the result file).

    Returns
    -------
    table : dict
        The table with the paths of the files found, resolved.
    relocated : bool
        Whether a file was found elsewhere than at its recorded path.

    Raises
    ------
    InputError
        A file missing (the places looked at named) or changed since the run.
    """
    relocated = False

    def locate(value: str, key: str) -> str:
        nonlocal relocated
        rec = records.get(value) or records.get(str(Path(value).resolve())) or {}
        candidates = [Path(value)]
        if rdir is not None:
            if isinstance(rec.get("relative"), str):
                candidates.append(rdir / rec["relative"])
            candidates.append(rdir / Path(value).name)
        found = next((c for c in candidates if c.is_file()), None)
        if found is None:
            also = "".join(f", {c}" for c in candidates[1:])
            raise InputError(f"rotor file {value} is missing (looked at {candidates[0]}{also}); this result records "
                             "no rotor data of its own, so its model needs the files the run read", source, None, key)
        relocated |= found != candidates[0]
        if isinstance(rec.get("sha256"), str):
            now = sha256_of(found)
            if now != rec["sha256"]:
                raise _changed(found, rec["sha256"], now, source, key)
        return str(found.resolve())

    new = dict(table)
    for key in FILE_KEYS:
        if isinstance(new.get(key), str):
            new[key] = locate(new[key], f"rotor.{key}")
    if isinstance(new.get("airfoils"), list):
        new["airfoils"] = [locate(a, f"rotor.airfoils[{i}]") if isinstance(a, str) else a
                           for i, a in enumerate(new["airfoils"])]
    return new, relocated


def check_followed_files(records: dict[str, dict], source: str) -> None:
    """Refuse a recorded file that is still at its recorded path but changed since the run.

    These include the files the readers follow (an OpenFAST deck's AeroDyn, blade and airfoil
    files), checked before reading where they were.

    Parameters
    ----------
    records : dict
        The recorded files by path (:func:`records_by_path`).
    source : str
        Named in errors (the result file).

    Raises
    ------
    InputError
        Naming the file and both digests, shortened.
    """
    for rec in records.values():
        path = Path(rec["path"])
        if isinstance(rec.get("sha256"), str) and path.is_file():
            now = sha256_of(path)
            if now != rec["sha256"]:
                raise _changed(path, rec["sha256"], now, source, "rotor")


def check_files_read(provenance: dict, files: tuple[Path, ...], source: str) -> None:
    """Refuse a rebuilt rotor whose files read differ, in number or digest, from those of the run.

    Parameters
    ----------
    provenance : dict
        The recorded provenance, with ``all_files_read``.
    files : tuple of Path
        :attr:`~calib.rotor.sources.RotorSource.files` of the rebuilt rotor, in reading order.
    source : str
        Named in errors (the result file).

    Raises
    ------
    InputError
        Another number of files, or a file changed since the run.
    """
    recorded = [r for r in provenance.get("files") or [] if isinstance(r, dict)]
    if len(recorded) != len(files):
        raise InputError(f"the rotor files now lead to {len(files)} files, the run read {len(recorded)} "
                         f"({', '.join(str(r.get('path')) for r in recorded)}): changed since the run", source,
                         None, "rotor")
    for rec, path in zip(recorded, files):
        if isinstance(rec.get("sha256"), str):
            now = sha256_of(path)
            if now != rec["sha256"]:
                raise _changed(path, rec["sha256"], now, source, "rotor")
