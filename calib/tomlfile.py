"""Reading a TOML settings file with errors that name the file (and the line and column of a syntax error)."""

from __future__ import annotations

import tomllib
from pathlib import Path

from calib.errors import InputError


def read_toml(path: str | Path, what: str = "settings file") -> dict:
    """The parsed TOML file at ``path``.

    Raises
    ------
    InputError
        ``what`` not found, not UTF-8 text, or not valid TOML (tomllib's message names the line
        and column).
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise InputError(f"{what} not found", src)
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", src) from None
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", src) from None
