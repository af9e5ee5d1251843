"""Cells, headers and units of a measurement file: decoding, delimiters, numbers (with a decimal comma),
units in the header or in a units row. The pieces :mod:`calib.measurements.reader` builds its table from."""

from __future__ import annotations

import codecs
import csv
import difflib
import re
from typing import Sequence


from calib.errors import InputError
from calib.types import CONDITION_FIELDS

from calib.measurements.units import FIXED_QUANTITY, UNITS, canonical_unit, normalize_name, quantity_of

#: Cell texts that mean "no value" (compared lower-case, after stripping blanks).
MISSING_CELLS = frozenset({"", "nan", "na", "n/a", "#n/a", "null", "none"})

DECIMAL_COMMA = re.compile(r"^[+-]?(\d+,\d*|,\d+)([eE][+-]?\d+)?$")
DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab"}
LINE_BREAK = re.compile(r"\r\n|\r|\n")
_MAGIC = (  # leading bytes of files people pick by mistake -> what they are
    (b"PK\x03\x04", "a zip archive (an .xlsx/.ods workbook is one: export the sheet as CSV)"),
    (b"\xd0\xcf\x11\xe0", "an OLE2 document (an .xls workbook: export the sheet as CSV)"),
    (b"\x89PNG", "a PNG image"), (b"\xff\xd8\xff", "a JPEG image"), (b"%PDF", "a PDF document"),
    (b"\x1f\x8b", "a gzip archive"), (b"\x89HDF", "an HDF5 file"), (b"\x93NUMPY", "a NumPy .npy file"),
)


def known_names_text() -> str:
    return (", ".join(list(CONDITION_FIELDS) + [n for n in FIXED_QUANTITY if n not in CONDITION_FIELDS])
            + ", root_flap_moment_blade<1-3>, root_edge_moment_blade<1-3>, cn@<r/R>, ct@<r/R>, fn@<r/R>, ft@<r/R>, "
              "<channel>_1p / _2p / _3p (harmonic amplitude), <channel>_1p_phase ... [deg], <channel>_sigma")


def decode(raw: bytes, src: str) -> tuple[str, list[str]]:
    """Text of a table file and a note on its encoding; refuses binary and non-UTF-8 files."""
    if raw.startswith(codecs.BOM_UTF8):
        encoding, note = "utf-8-sig", "encoding: UTF-8 with byte-order mark"
    elif raw.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        encoding, note = "utf-16", "encoding: UTF-16 with byte-order mark"
    else:
        for magic, what in _MAGIC:
            if raw.startswith(magic):
                raise InputError(f"not a text table: the file is {what}; expected a CSV text file "
                                 "(UTF-8, columns separated by comma, semicolon or tab)", src)
        if b"\x00" in raw[:1 << 16]:
            raise InputError("not a text table: the file contains NUL bytes (a binary file?); expected a "
                             "CSV text file (UTF-8, columns separated by comma, semicolon or tab)", src)
        encoding, note = "utf-8", None
    try:
        text = raw.decode(encoding)
    except UnicodeDecodeError as e:
        if encoding == "utf-16":
            raise InputError(f"not valid UTF-16 text (byte {e.start}): {e.reason}", src) from None
        start = e.start + (3 if encoding == "utf-8-sig" else 0)
        line = raw[:start].count(b"\n") + 1
        column = start - raw.rfind(b"\n", 0, start)
        raise InputError(f"not UTF-8 text: byte 0x{raw[start]:02x} at column {column} cannot be decoded; "
                         "save the table as UTF-8 ('CSV UTF-8' in a spreadsheet), or check that this is "
                         "the measurement table", src, line) from None
    bad = re.search(r"[\x00-\x08\x0e-\x1f\x7f]", text)
    if bad:
        line = text.count("\n", 0, bad.start()) + 1
        raise InputError(f"not a text table: control character U+{ord(bad.group()):04X} (a binary file?); "
                         "expected a CSV text file", src, line)
    return text, [note] if note else []


def split_line(text: str, delimiter: str, src: str | None = None, line: int | None = None) -> list[str]:
    """The cells of one line; a line the csv module refuses (a cell over its size limit) is an InputError.

    ``delimiter`` ``" "`` splits at runs of blanks (OpenFAST text output without tabs).
    """
    if delimiter == " ":
        return text.split()
    try:
        return next(csv.reader([text], delimiter=delimiter))
    except csv.Error as exc:
        raise InputError(f"cannot split the line into cells ({exc}); expected a CSV row of numbers", src,
                         line) from None


def _n_cells(text: str, delimiter: str) -> int:
    try:
        return len(split_line(text, delimiter))
    except InputError:
        return -1


def detect_delimiter(header: str, sample: Sequence[str]) -> str | None:
    """The delimiter (``,``, ``;`` or tab) that splits the header into the most columns,
    preferring one that splits the sample rows into as many (``None``: a single column)."""
    best = None
    for d in DELIMITERS:
        n = _n_cells(header, d)
        if n < 2:
            continue
        score = (all(_n_cells(s, d) == n for s in sample), n)
        if best is None or score > best[0]:
            best = (score, d)
    return None if best is None else best[1]


def parse_header(text: str, column: int) -> tuple[str, str | None]:
    """(normalized name, unit as written or None) of the header cell of 1-based ``column``.

    A cell that does not read as ``name [unit]`` keeps its whole text as the name (an unknown
    column, ignored with a note); an empty cell (a trailing delimiter) is named ``<column N>``.
    """
    name, unit = _split_unit(text)
    name = normalize_name(name)
    return (name, unit) if name else (f"<column {column}>", None)


def _split_unit(text: str) -> tuple[str, str | None]:
    """(name, unit) of a header cell ``name [unit]``, ``name_[unit]`` or ``name (unit)``; (text, None) otherwise.

    The unit is the last bracketed group, which must end the cell and hold no bracket itself;
    the name before it keeps at least one character. (A string scan: the regular expression
    this replaces took minutes on a cell with a few thousand blanks.)
    """
    t = text.strip()
    for open_, close in (("[", "]"), ("(", ")")):
        if not t.endswith(close):
            continue
        i = t.rfind(open_)
        unit = t[i + 1:-1]
        if i < 0 or open_ in unit or close in unit:
            return text, None
        name = t[:i].rstrip()
        if name.endswith("_") and len(name) > 1:
            name = name[:-1].rstrip()
        return (name, unit.strip()) if name else (text, None)
    return text, None


def declared_unit(column: str, unit: str | None, src: str, line: int | None, where: str = "") -> str | None:
    """:data:`UNITS` spelling of a known column's unit (``None`` when none was given).

    ``where`` names the cell in the message (`` in column 3 'RotPwr' of the units row``).
    """
    quantity = quantity_of(column)
    if quantity is None or unit is None:
        return None
    canon = canonical_unit(quantity, unit)
    if canon is None:
        raise InputError(f"unknown unit [{unit}] for {quantity}{where}; accepted units: "
                         f"{', '.join(UNITS[quantity])}", src, line, field=column)
    return canon


def unit_cell(cell: str) -> tuple[str, bool]:
    """(unit, bracketed) of a units-row cell ``(m/s)``, ``[kW]`` or ``m/s`` (``''`` for ``()``)."""
    c = cell.strip()
    if len(c) >= 2 and (c[0], c[-1]) in (("(", ")"), ("[", "]")):
        return c[1:-1].strip(), True
    return c, False


def is_number_cell(cell: str) -> bool:
    """True for a cell that reads as a number, with a decimal point or a decimal comma."""
    if DECIMAL_COMMA.match(cell):
        return True
    try:
        float(cell)
        return True
    except ValueError:
        return False


def is_units_row(cells: Sequence[str], names: Sequence[str]) -> bool:
    """True if ``cells``, the row right under the header, is a units row.

    A units row holds no number (but ``1``, a unit of coefficients), and at least one unit: a
    bracketed cell (``(s)``, ``[kW]``, ``(-)``) or, under a known column, a unit of that column's
    quantity (``kW`` under ``power``). A row of descriptions (``Wind speed at hub``) is not one.
    """
    evidence = False
    for cell, name in zip(cells, names):
        c = cell.strip()
        if not c or c.lower() in MISSING_CELLS:
            continue
        if c != "1" and is_number_cell(c):
            return False
        unit, bracketed = unit_cell(c)
        quantity = quantity_of(name)
        known = quantity is not None and c != "1" and canonical_unit(quantity, unit) is not None
        evidence = evidence or bracketed or known
    return evidence


def to_float(cell: str, decimal_comma: bool) -> float:
    """A cell as a float (ValueError if it is not a number)."""
    if decimal_comma:
        if "." in cell:
            raise ValueError("point in decimal-comma file")
        cell = cell.replace(",", ".")
    return float(cell)


def did_you_mean(name: str, candidates: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


def short_list(items: Sequence, n: int = 8) -> str:
    items = [str(i) for i in items]
    return ", ".join(items[:n]) + (f" ... ({len(items)} in all)" if len(items) > n else "")
