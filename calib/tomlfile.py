"""Reading a TOML settings file with errors that name the file (and the line and column of a syntax error)."""

from __future__ import annotations

import math
import re
import tomllib
from pathlib import Path

from calib.errors import InputError

_WHERE = re.compile(r"\s*\(at (?:line (?P<line>\d+), column (?P<column>\d+)|end of document)\)\s*$")


def read_toml(path: str | Path, what: str = "settings file", finite: bool = False) -> dict:
    """The parsed TOML file at ``path``.

    Parameters
    ----------
    finite : bool
        Refuse TOML's ``nan`` and ``inf`` literals anywhere in the file (for files none of
        whose settings is one), naming the key.

    Raises
    ------
    InputError
        ``what`` not found or unreadable, not UTF-8 text (line and column of the first bad byte),
        not valid TOML (line and column of the syntax error), an integer beyond 64 bits (key),
        or with ``finite`` a NaN or infinite number (key).
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
        data = tomllib.loads(text)
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
    bad = find_in_tree(data, _wide_integer)
    if bad:  # TOML 1.0: integers are 64-bit, a larger one "must" be an error (tomllib accepts it)
        raise InputError(f"not valid TOML: integer {bad[1]} is outside the 64-bit range TOML allows", src,
                         field=bad[0])
    bad = find_in_tree(data, _non_finite) if finite else None
    if bad:
        raise InputError(f"'{bad[0]}' must be a finite number, got {bad[1]!r}", src, field=bad[0])
    return data


def find_in_tree(node, predicate, key: str = ""):
    """(key, value) of the first leaf of a parsed TOML tree for which ``predicate`` is true, or
    None; keys are dotted, array items indexed (``stages[1].channels``)."""
    if not isinstance(node, (dict, list)) and predicate(node):
        return key, node
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        found = find_in_tree(v, predicate, f"{key}[{k}]" if isinstance(k, int) else (f"{key}.{k}" if key else str(k)))
        if found:
            return found
    return None


def _wide_integer(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and not -2 ** 63 <= v < 2 ** 63


def _non_finite(v) -> bool:
    return isinstance(v, float) and not math.isfinite(v)
