"""Which columns of a measurement table are read, and in which unit.

The header side of :func:`calib.measurements.reader.read_measurements`: the required
conditions and no duplicate (:func:`check_columns`), the unit of each known column from its
header or from the units row (:func:`declared_units`), the channels kept and their σ columns
(:func:`kept_channels`), a model's own channels read as given (:func:`model_specific_channels`)
and the notes on the columns ignored (:func:`ignored_column_notes`). A refusal names the file,
the header or units-row line and the column, with a close known name where there is one.
"""

from __future__ import annotations

from collections import Counter
from typing import Sequence

from calib.errors import InputError
from calib.measurements.cells import (MISSING_CELLS, declared_unit, did_you_mean, known_names_text, short_list,
                                      to_float, unit_cell)
from calib.measurements.openfast_out import CHANNELS as OPENFAST_CHANNELS
from calib.measurements.openfast_out import missing_hint
from calib.measurements.table import Table
from calib.measurements.units import FIXED_QUANTITY, REQUIRED_CONDITIONS, is_channel_name, quantity_of
from calib.types import CONDITION_FIELDS


def check_columns(table: Table) -> None:
    """Refuse duplicate columns and a missing required condition, naming the header line.

    Parameters
    ----------
    table : Table

    Raises
    ------
    InputError
        A column name twice (after :func:`~calib.measurements.units.normalize_name`), or one of
        :data:`~calib.measurements.units.REQUIRED_CONDITIONS` absent (with a close name or the
        OpenFAST channel read for it).
    """
    counts = Counter(table.names)  # a table exported transposed has tens of thousands of columns
    dupes = sorted(n for n, k in counts.items() if k > 1)
    if dupes:
        same = [r for r, n in zip(table.raw_names, table.names) if n == dupes[0]]
        raise InputError(f"duplicate column(s) {short_list(dupes)} (headers {short_list(list(map(repr, same)))})",
                         table.src, table.header_line, field=dupes[0])
    for req in REQUIRED_CONDITIONS:
        if req not in counts:
            raise InputError(f"missing required column '{req}'{_absent_hint(table, req)}; columns present: "
                             f"{short_list(table.raw_names, 30)}", table.src, table.header_line, field=req)


def _absent_hint(table: Table, name: str) -> str:
    """What to look for when a column ``name`` is absent: a close name, or the OpenFAST channel read for it."""
    if table.openfast is not None:
        return missing_hint(name, table.raw_names)
    return did_you_mean(name, [n for n in table.names if quantity_of(n) is None])


def declared_units(table: Table) -> dict[str, str | None]:
    """:data:`~calib.measurements.units.UNITS` spelling of each known column's unit, from its header or
    from the units row.

    Parameters
    ----------
    table : Table

    Returns
    -------
    dict
        Known column name -> unit (``None`` where none was given: SI).

    Raises
    ------
    InputError
        A unit in both the header and the units row, or an unknown unit (line and column named).
    """
    row_line, row = table.units_row or (None, [])
    declared = {}
    for i, (name, head) in enumerate(zip(table.names, table.header_units)):
        if quantity_of(name) is None:
            continue
        cell = row[i] if i < len(row) else ""
        where = f" in column {i + 1} '{table.raw_names[i]}'"
        if cell and head is not None:
            raise InputError(f"unit given twice{where}: [{head}] in the header (line {table.header_line}) and "
                             f"{cell!r} in the units row; give a column's unit either in brackets in the header "
                             "or in the units row", table.src, row_line, field=name)
        if cell:
            declared[name] = declared_unit(name, unit_cell(cell)[0] or None, table.src, row_line,
                                            where + " of the units row")
        elif table.openfast is not None:   # OpenFAST writes every unit; a gap is a damaged file, not SI
            raise InputError(f"no unit{where} of the units row; OpenFAST writes one for every channel",
                             table.src, row_line, field=name)
        else:
            declared[name] = declared_unit(name, head, table.src, table.header_line, where)
    return declared


def model_specific_channels(table: Table, needed: list[str]) -> list[str]:
    """Requested columns whose names calib does not know (a model's own outputs, e.g. an FMU
    mapping's ``shaft_power``): read as given; a unit on them is refused, since it cannot be
    converted.

    Parameters
    ----------
    table : Table
    needed : list of str
        The columns to read (conditions, channels, σ).

    Returns
    -------
    list of str
        Those of ``needed`` without a known quantity, in order.

    Raises
    ------
    InputError
        A unit in the header or the units row of such a column (line and column named).
    """
    out = []
    row_line, row = table.units_row or (None, [])
    for name in needed:
        if quantity_of(name) is not None:
            continue
        i = table.names.index(name)
        unit, line = table.header_units[i], table.header_line
        if unit is None and i < len(row) and row[i]:
            unit, line = row[i], row_line
        if unit is not None and unit.strip("()[] ") not in ("", "-"):
            raise InputError(f"column {i + 1} '{table.raw_names[i]}' is a channel calib knows no quantity of, so "
                             f"its unit {unit!r} cannot be converted: give its values in the model's unit "
                             "(the mapping's channel_unit) without a unit", table.src, line, field=name)
        out.append(name)
    return out


def kept_channels(table: Table, channels: Sequence[str] | None, allow_no_channels: bool) -> tuple[list, list]:
    """The channels to keep and their ``_sigma`` columns (empty when the table gives no σ).

    Parameters
    ----------
    table : Table
    channels : sequence of str or None
        Channels asked for (a model's own output names included); ``None``: every known channel
        column present.
    allow_no_channels : bool
        Accept a table without channels.

    Returns
    -------
    channels, sigma_columns : list of str

    Raises
    ------
    InputError
        A channel asked for is absent; no channel (unless allowed); σ for some channels only.
    """
    src, line = table.src, table.header_line
    present = [n for n in table.names if is_channel_name(n)]
    present_set, name_set = set(present), set(table.names)
    if channels is not None:   # a model's own output names (an FMU mapping's) are channels when asked for
        present_set |= {c for c in channels if c in name_set and c not in CONDITION_FIELDS
                        and not c.endswith("_sigma")}
    channels = present if channels is None else list(channels)
    for c in channels:
        if c not in present_set:
            raise InputError(f"channel '{c}' is not in the file{_absent_hint(table, c)}; channel columns present: "
                             f"{short_list(present, 30) or '(none)'}", src, line, field=c)
    if not channels and not allow_no_channels:
        if table.openfast is not None:
            raise InputError("no calib channel among the OpenFAST channels; read are: " + "; ".join(
                f"{c} from {', '.join(names)}" for c, names in OPENFAST_CHANNELS.items()
                if c not in REQUIRED_CONDITIONS), src, line)
        guesses = [f"'{r}'{did_you_mean(n, list(FIXED_QUANTITY))}" for r, n in zip(table.raw_names, table.names)
                   if quantity_of(n) is None][:30]
        raise InputError("no channel columns (e.g. power, thrust, cn@0.30; a unit goes in brackets: "
                         f"'power [kW]'); unrecognised columns: {short_list(guesses, 30) or '(none)'}", src, line)
    sig_cols = [f"{c}_sigma" for c in channels]
    if not any(s in name_set for s in sig_cols):
        return channels, []
    missing = [s for s in sig_cols if s not in name_set]
    if missing:
        given = [s for s in sig_cols if s in name_set]
        raise InputError(f"sigma given for some channels ({', '.join(given)}) but not for {', '.join(missing)}; "
                         "give a _sigma column for every kept channel or none", src, line, field=missing[0])
    return channels, sig_cols


def ignored_column_notes(table: Table, rows: list, decimal_comma: bool) -> list[str]:
    """Notes naming the columns that are not known names: non-numeric ones and numeric ones.

    Parameters
    ----------
    table : Table
    rows : list of (int, list of str)
        The data rows (:func:`calib.measurements.rows.split_rows`).
    decimal_comma : bool
        Whether a comma is the decimal separator.

    Returns
    -------
    list of str
        Zero to two notes (the numeric ones with a close known name where there is one).
    """
    def is_number(cell: str) -> bool:
        try:
            to_float(cell, decimal_comma)
            return True
        except ValueError:
            return False

    ignored_text, ignored_numeric = [], []
    for i, n in enumerate(table.names):
        if quantity_of(n) is not None:
            continue
        column = [cells[i] for _, cells in rows if i < len(cells) and cells[i].lower() not in MISSING_CELLS]
        (ignored_numeric if column and all(map(is_number, column)) else ignored_text).append(i)
    raw, names, notes = table.raw_names, table.names, []
    if ignored_text:
        notes.append(f"ignored non-numeric column(s): {short_list([raw[i] for i in ignored_text], 30)}")
    if ignored_numeric:
        named = short_list([raw[i] + did_you_mean(names[i], list(FIXED_QUANTITY)) for i in ignored_numeric[:30]]
                            + [raw[i] for i in ignored_numeric[30:]], 30)
        notes.append(f"ignored unrecognised numeric column(s): {named}; known names: {known_names_text()}")
    return notes
