"""Errors raised on bad input.

Every error about user input names *where* the problem is (file, line, column or
variable) and *what was expected*, so that a user can fix the input without reading
a traceback.
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Iterable


class CalibError(Exception):
    """Base class of all errors raised deliberately by ``calib``."""


class InputError(CalibError, ValueError):
    """Bad user input: a file, a table, an argument.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    source : str or Path, optional
        The file (or the name of the object) the input came from.
    line : int, optional
        1-based line (or row) number in ``source``.
    field : str, optional
        Column, key or variable name.
    """

    def __init__(self, message: str, source: str | Path | None = None,
                 line: int | None = None, field: str | None = None):
        self.message = message
        self.source = None if source is None else str(source)
        self.line = line
        self.field = field
        where = []
        if self.source is not None:
            where.append(self.source)
        if line is not None:
            where.append(f"line {line}")
        if field is not None:
            where.append(f"field '{field}'")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class ModelError(CalibError, RuntimeError):
    """A forward model could not be set up or evaluated (not a per-point failure)."""


def unknown_key(key: str, valid: Iterable[str], where: str = "", label: str = "valid keys here") -> str:
    """The message for a key that is not one of ``valid``: the key, the valid ones, and the
    closest valid key when one is close (``difflib``), e.g. "unknown key 'calibration.sigam';
    valid keys here: ... (did you mean 'sigma'?)"."""
    valid = list(valid)
    close = difflib.get_close_matches(str(key), valid, n=2, cutoff=0.6)
    hint = f" (did you mean {' or '.join(repr(where + c) for c in close)}?)" if close else ""
    return f"unknown key '{where}{key}'; {label}: {', '.join(valid)}{hint}"
