"""Writing results to disk: JSON-ready values, atomic files, the package versions a result records."""

from __future__ import annotations

import enum
import functools
import os
import platform
import tempfile
from pathlib import Path

import numpy as np


def package_versions() -> dict[str, str]:
    """Versions of Python and the numerical packages the result depends on (a new dict each call)."""
    return dict(_installed_versions())


@functools.lru_cache(maxsize=1)
def _installed_versions() -> tuple[tuple[str, str], ...]:
    """The versions of :func:`package_versions`, read from the installed metadata once per
    process (reading them took 40 ms, a tenth of a paper-size calibration)."""
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for name in ("calib", "numpy", "scipy", "casadi", "matplotlib"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "unknown"
    return tuple(out.items())


def atomic_write(path: Path, writer) -> None:
    """Write ``path`` through ``writer(temporary_path)`` and a rename, so that the file is
    either the old one or the whole new one, never half written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        writer(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def write_text_synced(text: str):
    """A ``writer`` for :func:`atomic_write` that writes ``text`` and syncs it to disk (the blocks
    are on disk before the rename makes the name final)."""
    def write(tmp):
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
    return write


def write_npz_synced(arrays: dict):
    """A ``writer`` for :func:`atomic_write` that writes ``arrays`` as a compressed NPZ and syncs it."""
    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez_compressed(f, **arrays)
            f.flush()
            os.fsync(f.fileno())
    return write


def jsonable(x, fallback=None):
    """``x`` with numpy scalars and arrays, paths and enums turned into JSON types, recursively;
    any other object is kept, or passed through ``fallback`` (e.g. ``str``) when given."""
    if isinstance(x, dict):
        return {str(k): jsonable(v, fallback) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v, fallback) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist(), fallback)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, enum.Enum):
        return x.value
    if fallback is not None and not (isinstance(x, (str, int, float, bool)) or x is None):
        return fallback(x)
    return x
