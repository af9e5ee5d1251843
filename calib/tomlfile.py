"""Reading a TOML settings file with errors that name the file (and the line and column of a syntax error)."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from calib.errors import InputError

_WHERE = re.compile(r"\s*\(at (?:line (?P<line>\d+), column (?P<column>\d+)|end of document)\)\s*$")


def read_toml(path: str | Path, what: str = "settings file") -> dict:
    """The parsed TOML file at ``path``.

    Raises
    ------
    InputError
        ``what`` not found or unreadable, not UTF-8 text (line and column of the first bad byte),
        or not valid TOML (line and column of the syntax error).
    """
    path = Path(path)
    src = str(path)
    try:
        raw = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        raise InputError(f"{what} not found", src) from None
    except OSError as exc:
        raise InputError(f"cannot read the {what} ({exc.strerror or exc})", src) from None
    try:
        text = raw.decode("utf-8-sig")  # a byte-order mark (Windows editors) is not part of the TOML
    except UnicodeDecodeError as exc:
        start = exc.start + (3 if raw.startswith(b"\xef\xbb\xbf") else 0)
        line = raw[:start].count(b"\n") + 1
        column = start - raw.rfind(b"\n", 0, start)
        raise InputError(f"not a UTF-8 text file: byte 0x{raw[start]:02x} at column {column} cannot be decoded; "
                         f"expected a TOML {what} in UTF-8", src, line) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        message = str(exc)  # "... (at line 3, column 7)" or "... (at end of document)"
        m = _WHERE.search(message)
        line = None
        if m and m.group("line"):
            line = int(m.group("line"))
        elif m:
            line = max(1, text.count("\n") + (0 if text.endswith("\n") else 1))
        raise InputError(f"not valid TOML: {message}", src, line) from None
    except RecursionError:
        raise InputError("not valid TOML: nesting too deep", src) from None
