"""OpenFAST input files as text: lines, tokens, numeric tables and ``value  Keyword`` lookup.

- Line helpers shared by the AeroDyn readers (:mod:`calib.rotor.aerodyn_blade`,
  :mod:`calib.rotor.aerodyn_polar`, :mod:`calib.rotor.aerodyn_main`): reading a file into
  lines as OpenFAST splits them, comments, tokens, keyword search, numbers, counts and
  numeric tables of ``n`` rows.
- :class:`InputFileValues`: the ``value  Keyword  - description`` lines of any OpenFAST input
  file, looked up by keyword (:class:`KeyedValue` per line; also used by
  :mod:`calib.rotor.openfast`), and :func:`resolve_input_file` for the file names they give.

Every error is an :class:`~calib.errors.InputError` naming the file, the 1-based line
and the field (column or keyword as spelled in the file).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from calib.errors import InputError

TOKEN = re.compile(r'"([^"]*)"|(\S+)')
_LINE_BREAK = re.compile(r"\r\n|\r|\n")


# ---------------------------------------------------------------- low-level helpers
def read_lines(path) -> tuple[list[str], str]:
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise InputError("file not found", src) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc})", src) from None
    # lines end at \n, \r\n or \r only, as OpenFAST reads them: str.splitlines also splits at form
    # feeds, \x85 and U+2028, and every later line number in a message would be off
    lines = _LINE_BREAK.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines, src


def is_comment(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith("!") or s.startswith("#")


def tokens_of(line: str) -> list[str]:
    """Whitespace tokens before an inline ``!`` comment."""
    return line.split("!", 1)[0].split()


def find_keyword(lines, key: str, start: int, stop_keys=()) -> int | None:
    """Index of the first line (>= start) whose second token is ``key``.

    The search stops (returns None) at a line whose second token is in ``stop_keys``.
    """
    key = key.lower()
    stops = {k.lower() for k in stop_keys}
    for i in range(start, len(lines)):
        if is_comment(lines[i]):
            continue
        tok = tokens_of(lines[i])
        if len(tok) >= 2:
            word = tok[1].lower()
            if word == key:
                return i
            if word in stops:
                return None
    return None


def read_number(text: str, src: str, line: int, field: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"expected a number, got {text!r}", src, line, field) from None
    if not np.isfinite(value):
        raise InputError(f"expected a finite number, got {text!r}", src, line, field)
    return value


def read_count(text: str, src: str, line: int, field: str, minimum: int = 1) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"expected an integer count, got {text!r}", src, line, field) from None
    if value < minimum:
        raise InputError(f"must be >= {minimum}, got {value}", src, line, field)
    return value


def is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_rows(lines, start: int, n_rows: int, names, n_required: int, src: str,
               count_field: str, count_line: int, end_keywords=frozenset()):
    """Read ``n_rows`` numeric rows from ``lines[start:]``, skipping comment lines.

    Returns (values (n_rows, n_cols) with NaN for absent optional columns, line numbers
    (1-based), index of the line after the last row).
    """
    rows, row_lines = [], []
    i = start
    while len(rows) < n_rows and i < len(lines):
        line = lines[i]
        i += 1
        if is_comment(line):
            continue
        tok = tokens_of(line)
        if len(tok) >= 2 and tok[1].lower() in end_keywords and not is_number(tok[1]):
            i -= 1
            break
        if len(tok) < n_required:
            raise InputError(f"expected {n_required} columns ({', '.join(names[:n_required])}), "
                             f"found {len(tok)}", src, i, names[len(tok)])
        vals = [read_number(t, src, i, names[k]) for k, t in enumerate(tok[:len(names)])]
        vals += [np.nan] * (len(names) - len(vals))
        rows.append(vals)
        row_lines.append(i)
    if len(rows) < n_rows:
        raise InputError(f"{count_field} = {n_rows} but only {len(rows)} data rows follow "
                         f"(table ends at line {i})", src, count_line, count_field)
    return np.array(rows, dtype=float).reshape(n_rows, len(names)), np.array(row_lines), i


def check_increasing(values, row_lines, src, field, what):
    bad = np.flatnonzero(np.diff(values) <= 0)
    if bad.size:
        k = bad[0] + 1
        raise InputError(f"{what} must be strictly increasing: {values[k]:g} follows {values[k - 1]:g}",
                         src, int(row_lines[k]), field)


# ---------------------------------------------------------------- keyword lookup
@dataclass(frozen=True)
class KeyedValue:
    """One ``value  Keyword`` line of an OpenFAST input file.

    Attributes
    ----------
    text : str
        The value as written, quotes removed.
    quoted : bool
        Whether the value was quoted.
    line : int
        1-based line number.
    key : str
        The keyword as spelled in the file.
    """

    text: str
    quoted: bool
    line: int
    key: str


class InputFileValues:
    """The ``value  Keyword  - description`` lines of an OpenFAST input file, by keyword.

    OpenFAST reads its input files line by line in a fixed order that changes between
    versions; looking values up by their keyword instead reads every generation that
    keeps the keyword. Keywords match case-insensitively (``PLExp`` = ``PLexp``); the first
    occurrence wins. Every error names the file, the line and the keyword.

    Parameters
    ----------
    path : str or Path
        The input file.
    """

    def __init__(self, path):
        self.path = Path(path)
        lines, self.source = read_lines(path)
        self.n_lines = len(lines)
        self._values: dict[str, KeyedValue] = {}
        for i, line in enumerate(lines):
            if is_comment(line):
                continue
            tokens = list(TOKEN.finditer(line))
            if len(tokens) < 2 or tokens[1].group(1) is not None:
                continue
            first = tokens[0]
            quoted = first.group(1) is not None
            text = first.group(1) if quoted else first.group(2)
            key = tokens[1].group(2)
            self._values.setdefault(key.lower(), KeyedValue(text, quoted, i + 1, key))

    def __contains__(self, key: str) -> bool:
        return key.lower() in self._values

    def get(self, key: str) -> KeyedValue | None:
        """The value of ``key``, or None when the file does not have it."""
        return self._values.get(key.lower())

    def require(self, key: str, expected: str) -> KeyedValue:
        """The value of ``key``; an :class:`InputError` naming ``expected`` when absent."""
        value = self.get(key)
        if value is None:
            raise InputError(f"keyword {key} not found; expected a line '<{expected}>  {key}'",
                             self.source, None, key)
        return value

    def number(self, key: str, expected: str = "number", allow_default: bool = False) -> float | None:
        """A finite number; ``"default"`` gives None when ``allow_default``."""
        value = self.require(key, expected)
        if allow_default and value.text.strip().lower() == "default":
            return None
        try:
            out = float(value.text)
        except ValueError:
            hint = ' or "default"' if allow_default else ""
            raise InputError(f"expected {expected}{hint}, got {value.text!r}", self.source, value.line,
                             value.key) from None
        if not np.isfinite(out):
            raise InputError(f"expected a finite {expected}, got {value.text!r}", self.source, value.line,
                             value.key)
        return out

    def integer(self, key: str, expected: str = "integer switch") -> int:
        """An integer (switches, counts)."""
        value = self.require(key, expected)
        try:
            return int(value.text)
        except ValueError:
            raise InputError(f"expected an {expected}, got {value.text!r}", self.source, value.line,
                             value.key) from None

    def flag(self, key: str) -> bool:
        """A logical flag (``True``/``False``, ``T``/``F``, any case)."""
        value = self.require(key, "True or False")
        word = value.text.strip().lower()
        if word in ("true", "t"):
            return True
        if word in ("false", "f"):
            return False
        raise InputError(f"expected True or False, got {value.text!r}", self.source, value.line, value.key)

    def file(self, key: str, required: bool = True) -> Path | None:
        """The file named by ``key``, resolved relative to this file's folder.

        ``"unused"`` or an empty name gives None when not ``required``.

        Raises
        ------
        InputError
            The keyword is missing, the name is ``"unused"`` while ``required``, or the
            file does not exist (the error names this file, the line and ``key``).
        """
        value = self.require(key, "quoted file name")
        return resolve_input_file(value.text, self, value.line, value.key, required)


def resolve_input_file(name: str, referrer: InputFileValues, line: int, key: str,
                       required: bool = True) -> Path | None:
    """Resolve a file name written in an OpenFAST input file.

    Relative names are relative to the folder of the referring file (OpenFAST's rule);
    Windows separators are accepted.
    """
    text = name.strip()
    if text == "" or text.lower() in ("unused", "none"):
        if required:
            raise InputError(f"a file is needed here, got {name!r}", referrer.source, line, key)
        return None
    text = text.replace("\\", "/")
    path = Path(text)
    if not path.is_absolute() and not PureWindowsPath(name).is_absolute():
        path = referrer.path.parent / PurePosixPath(text)
    try:
        exists = path.is_file()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise InputError(f"cannot use the file name it gives: {name[:80]!r}{'...' if len(name) > 80 else ''} "
                         f"({exc.strerror or exc})", referrer.source, line, key) from None
    if not exists:
        raise InputError(f"the file it names does not exist: {name!r} (looked for {path})",
                         referrer.source, line, key)
    return path

