"""A measurement file split into its parts: header, units row and data lines.

:func:`read_text` reads and decodes the file (refusing missing, unreadable and binary
files); :func:`read_table` splits the text into a :class:`Table`, as a CSV
(:func:`_csv_table`: delimiter detected, maybe a units row under the header) or as
OpenFAST text output (:func:`_openfast_table`: title lines, channel names, units row).
:mod:`calib.measurements.reader` reads the values from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calib.errors import InputError
from calib.measurements.cells import (DELIMITERS, LINE_BREAK, decode, detect_delimiter, is_units_row, parse_header,
                                      split_line)
from calib.measurements.openfast_out import MAX_TITLE_LINES, ChannelMap, channel_row, map_channels, refuse_binary


@dataclass
class Table:
    """A table file split into its parts (see :func:`read_table`).

    Attributes
    ----------
    src : str
        The file.
    header_line : int
        Line of the header (channel-name) row.
    delimiter : str
        ``,``, ``;``, tab, or ``" "`` (runs of blanks, OpenFAST output without tabs).
    raw_names : list of str
        The header cells as written (``<column N>`` for an empty one).
    names : list of str
        The names the loader compares: normalized, OpenFAST channels as calib names.
    header_units : list of (str or None)
        The unit in brackets of each header cell.
    lines : list of (int, str)
        The data lines.
    units_row : (int, list of str) or None
        Line and cells of a units row under the header.
    openfast : ChannelMap or None
        The channel mapping of an OpenFAST text output.
    """

    src: str
    header_line: int
    delimiter: str
    raw_names: list
    names: list
    header_units: list
    lines: list
    units_row: tuple | None = None
    openfast: ChannelMap | None = None


def read_text(path: Path) -> tuple[str, list[str]]:
    """Text of a table file and a note on its encoding; refuses missing, unreadable and binary files."""
    src = str(path)
    try:
        raw = path.read_bytes()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        raise InputError("file not found", src) from None
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise InputError(f"cannot read the file ({exc.strerror or exc})", src) from None
    refuse_binary(path)
    return decode(raw, src)


def read_table(text: str, path: Path, notes: list[str]) -> Table:
    """Split a table's text into header, units row and data lines (a CSV or an OpenFAST text output)."""
    src = str(path)
    # lines end at \n, \r\n or \r only: str.splitlines also splits at form feeds, \x85 and U+2028,
    # which editors do not, and every later line number would be off
    lines = [(i + 1, ln) for i, ln in enumerate(LINE_BREAK.split(text))
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty file: expected a header line and at least one data row", src)
    k = channel_row(lines, path)
    if k is None and path.suffix.lower() == ".out":
        raise InputError(f"not OpenFAST text output: no channel-name row starting with 'Time' over a units row "
                         f"starting with '(s)' in the first {MAX_TITLE_LINES} lines", src, field="Time")
    return _csv_table(lines, src, notes) if k is None else _openfast_table(lines, k, src, notes)


def _csv_table(lines: list[tuple[int, str]], src: str, notes: list[str]) -> Table:
    """A CSV table: the header on the first line, maybe a units row, then the data lines."""
    header_line, header = lines[0]
    delimiter = detect_delimiter(header, [t for _, t in lines[1:6]])
    if delimiter is None:
        raise InputError(f"found a single column {header.strip()!r}; expected columns separated by a comma, "
                         "a semicolon or a tab", src, header_line)
    notes.append(f"delimiter: {DELIMITERS[delimiter]} (detected)")
    raw_names = [h.strip() for h in split_line(header, delimiter, src, header_line)]
    parsed = [parse_header(h, i + 1) for i, h in enumerate(raw_names)]
    raw_names = [h or n for h, (n, _) in zip(raw_names, parsed)]
    table = Table(src, header_line, delimiter, raw_names, [n for n, _ in parsed], [u for _, u in parsed], lines[1:])
    if len(lines) > 1:
        line_no, text = lines[1]
        cells = split_line(text, delimiter, src, line_no)
        if is_units_row(cells, table.names):
            table.units_row, table.lines = (line_no, [c.strip() for c in cells]), lines[2:]
            notes.append(f"units row on line {line_no}")
    return table


def _openfast_table(lines: list[tuple[int, str]], k: int, src: str, notes: list[str]) -> Table:
    """An OpenFAST text output: title lines, the channel names on ``lines[k]``, the units row, the time rows."""
    header_line, header = lines[k]
    units_line, units = lines[k + 1]
    delimiter = "\t" if "\t" in header else " "
    raw_names = [h.strip() for h in split_line(header, delimiter, src, header_line)]
    channels = map_channels(raw_names)
    unit_cells = [c.strip() for c in split_line(units, delimiter, src, units_line)]
    separated = "tabs" if delimiter == "\t" else "blanks"
    notes.append(f"OpenFAST text output: {k} title line(s), channel names on line {header_line}, units on line "
                 f"{units_line}, columns separated by {separated}")
    notes.extend(channels.notes)
    return Table(src, header_line, delimiter, raw_names, channels.names, [None] * len(raw_names), lines[k + 2:],
                  (units_line, unit_cells), channels)
