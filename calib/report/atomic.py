"""Output files written under a temporary name in the same folder, then renamed.

A reader (or a user pressing Ctrl-C) never finds a truncated file under its final name:
until the rename, the bytes live in ``.<name>.<random>.tmp`` beside it; the rename
(:func:`os.replace`) is atomic on one file system. On any exception, including
:class:`KeyboardInterrupt` from SIGINT, the temporary file is removed; only a hard kill
(SIGKILL, power loss) can leave one behind, and it always carries the ``TEMP_PREFIX``
prefix and the ``TEMP_SUFFIX`` suffix.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

TEMP_PREFIX = "."
TEMP_SUFFIX = ".tmp"


def is_temporary(path: str | Path) -> bool:
    """Whether ``path`` names a temporary file of this module (hidden, ``.tmp`` suffix)."""
    name = Path(path).name
    return name.startswith(TEMP_PREFIX) and name.endswith(TEMP_SUFFIX)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds.

    Parameters
    ----------
    path : str or Path
        Final file name. Its folder is created if missing.

    Yields
    ------
    Path
        ``<folder>/.<name>.<random>.tmp``: write the complete file there.

    Notes
    -----
    The data are flushed to disk (``fsync``) before the rename, so the final name never
    points at a file whose blocks are not yet written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:
        fd, name = tempfile.mkstemp(dir=path.parent, prefix=f"{TEMP_PREFIX}{path.name}.", suffix=TEMP_SUFFIX)
        tmp = Path(name)
        os.close(fd)
        yield tmp
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if tmp is not None and tmp.exists():
            tmp.unlink()


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file and a rename; returns ``path``."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return path


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` through a temporary file and a rename; returns ``path``."""
    return atomic_write_bytes(path, text.encode(encoding))
