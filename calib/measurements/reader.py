"""Measurement tables: CSV and OpenFAST-output reading with units, noise models, synthetic measurements.

A measurement table holds, per operating point k, the conditions u_k and the measured
outputs z_k of some model channels, optionally with their 1-σ noise.

:func:`read_measurements` lives here with the checks of columns, units and values; the file
is split into header, units row and data lines by :mod:`calib.measurements.table`, and its
cells are read by :mod:`calib.measurements.cells`.

CSV layout
----------
Optional comment lines (starting with ``#``), one header line, then one row per record.
Columns (order free; names are case-insensitive, spaces and hyphens count as ``_``):

- conditions: ``wind_speed`` [m/s], ``rotor_speed`` [rpm], ``pitch`` [deg] (required);
  ``air_density`` [kg/m^3] (optional, default 1.225), ``yaw`` [deg] (optional, default 0);
- channels: ``power`` [W], ``thrust`` [N], ``torque`` [N m], ``root_flap_moment`` [N m],
  ``root_edge_moment`` [N m], and spanwise channels ``<q>@<r/R>`` with ``q`` in
  ``cn``, ``ct`` (force coefficients [-]) or ``fn``, ``ft`` (force per unit length [N/m]),
  e.g. ``cn@0.30`` is the normal-force coefficient at r/R = 0.30;
- noise: ``<channel>_sigma``, the 1-σ noise of that channel, in the same unit.

A header may give a unit as ``power [kW]``, ``Power_[kW]`` (OpenFAST style) or
``power (kW)``; units are case-insensitive (``kw`` is kW, ``mw`` is MW, never milliwatt)
and converted to SI on load (see :mod:`calib.measurements.units`). Without a unit
SI is assumed. Rows with the same conditions are *repeated records*;
:func:`noise_from_repeats` estimates the noise from them.

Units may instead stand in a *units row* right under the header, as data loggers and
OpenFAST write them (``(m/s)``, ``[kW]``, ``kN-m``, ``(-)``): a row with no number and at
least one unit (a bracketed cell, or a unit of its column's quantity) is one. A column's
unit either in brackets in the header or in the units row: both is refused.

OpenFAST text output (``.out``: title lines, a channel-name row starting with ``Time``, a
units row, the time rows; tabs or blanks) is recognised from its content and read with the
OpenFAST channel names mapped to calib's, and its time series refused, averaged into one
operating point or read row by row (``time_series``; :mod:`calib.measurements.openfast_out`). The binary
``.outb`` is refused.

Files as spreadsheets and loggers export them are accepted, and what was done is said in
:attr:`Measurements.notes`:

- encoding UTF-8, with or without byte-order mark, or UTF-16 with byte-order mark (Excel's
  "Unicode text"); anything else, including binary files (an ``.xlsx`` workbook, an image),
  is refused with :class:`~calib.errors.InputError`;
- the delimiter (comma, semicolon or tab) is detected from the header and the first rows;
- a *decimal comma* (``8,5``) is accepted when the delimiter is a semicolon or a tab: the
  comma is then read as the decimal separator in the whole file, and a cell with a point
  (``1.500``, possibly a thousands separator) is refused as ambiguous;
- columns that are not known names are ignored: non-numeric ones (timestamps, IDs) and
  numeric ones are named in separate notes;
- a missing value (empty cell, ``nan``, ``NA``, ``N/A``, ``#N/A``, ``null``, or a row cut
  short) in a column that is needed is refused with file, line and column, or, with
  ``drop_incomplete_rows=True``, the row is dropped and the count reported.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Sequence

import numpy as np

from calib.errors import InputError
from calib.measurements.cells import (DECIMAL_COMMA, MISSING_CELLS, declared_unit, did_you_mean, is_number_cell,
                                      known_names_text, short_list, split_line, to_float, unit_cell)
from calib.measurements.data import Measurements, sha256_of
from calib.measurements.openfast_out import CHANNELS as OPENFAST_CHANNELS
from calib.measurements.openfast_out import TIME_SERIES_MODES, average, missing_hint, time_rows
from calib.measurements.table import Table, read_table, read_text
from calib.measurements.units import FIXED_QUANTITY, REQUIRED_CONDITIONS, UNITS, is_channel_name, quantity_of, si_unit
from calib.types import CONDITION_DEFAULTS, CONDITION_FIELDS, OperatingConditions


def _check_columns(table: Table) -> None:
    """Refuse duplicate columns and a missing required condition, naming the header line."""
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


def _declared_units(table: Table) -> dict[str, str | None]:
    """:data:`UNITS` spelling of each known column's unit, from its header or from the units row.

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


def _model_specific_channels(table: Table, needed: list[str]) -> list[str]:
    """Requested columns whose names calib does not know (a model's own outputs, e.g. an FMU
    mapping's ``shaft_power``): read as given; a unit on them is refused, since it cannot be
    converted.

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


def _cells_error(table: Table, n_cells: int, line_no: int) -> InputError:
    hint = ("; numbers with a decimal comma need columns separated by ';' or tab"
            if table.delimiter == "," and n_cells > len(table.names) else "")
    return InputError(f"row has {n_cells} cells, header has {len(table.names)}{hint}", table.src, line_no)


def _split_rows(table: Table) -> list[tuple[int, list[str]]]:
    """The data lines as (line number, stripped cells); a row longer than the header is refused."""
    rows = []
    for line_no, t in table.lines:
        cells = split_line(t, table.delimiter, table.src, line_no)
        if len(cells) > len(table.names):
            raise _cells_error(table, len(cells), line_no)
        rows.append((line_no, [c.strip() for c in cells]))
    return rows


def _kept_channels(table: Table, channels: Sequence[str] | None, allow_no_channels: bool) -> tuple[list, list]:
    """The channels to keep and their ``_sigma`` columns (empty when the table gives no σ)."""
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


def _ignored_column_notes(table: Table, rows: list, decimal_comma: bool) -> list[str]:
    """Notes naming the columns that are not known names: non-numeric ones and numeric ones."""
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


def _cell_value(table: Table, cells: list[str], i: int, name: str, line_no: int, decimal_comma: bool,
                drop_incomplete_rows: bool) -> float | None:
    """The number in cell ``i`` of a row (``None``: missing, the row is to be dropped); refuses a bad cell."""
    src, where = table.src, f"column {i + 1} '{table.raw_names[i]}'"
    drop_hint = ("; to drop incomplete rows instead, pass drop_incomplete_rows=True "
                 "(workflow: [measurements] drop_incomplete_rows = true)")
    if i >= len(cells) or cells[i].lower() in MISSING_CELLS:
        if drop_incomplete_rows:
            return None
        if i >= len(cells):
            e = _cells_error(table, len(cells), line_no)
            raise InputError(e.message + f" (no value for {where})" + drop_hint, src, line_no, field=name)
        what = "empty cell" if not cells[i] else repr(cells[i])
        raise InputError(f"missing value ({what}) in {where}: expected a finite number{drop_hint}",
                         src, line_no, field=name)
    cell = cells[i]
    try:
        x = to_float(cell, decimal_comma)
    except ValueError:
        if decimal_comma and "." in cell and is_number_cell(cell.replace(".", "")):
            raise InputError(f"ambiguous number {cell!r} in {where}: this file uses a decimal comma, so a point "
                             "could be a thousands separator; export the table without thousands separators",
                             src, line_no, field=name) from None
        raise InputError(f"not a number: {cell!r} in {where}", src, line_no, field=name) from None
    if not np.isfinite(x):
        raise InputError(f"value is {cell!r} in {where}; every cell must be a finite number", src, line_no, field=name)
    return x


def _parse_values(table: Table, rows: list, needed: list[str], col_of: dict, decimal_comma: bool,
                  drop_incomplete_rows: bool, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The needed cells as numbers, shape (n_kept, n_needed), and the indices of the rows kept.

    A row with a missing value is refused, or dropped (``drop_incomplete_rows``, noted).
    """
    data = np.full((len(rows), len(needed)), np.nan)
    incomplete = []
    for r, (line_no, cells) in enumerate(rows):
        values = [_cell_value(table, cells, col_of[n], n, line_no, decimal_comma, drop_incomplete_rows)
                  for n in needed]
        if any(v is None for v in values):
            incomplete.append(r)
        else:
            data[r] = values
    kept = np.arange(len(rows))
    if incomplete:
        if len(incomplete) == len(rows):
            raise InputError(f"every one of the {len(rows)} rows has a missing value in a needed column "
                             f"({', '.join(needed)})", table.src, table.header_line)
        notes.append(f"dropped {len(incomplete)} of {len(rows)} rows with a missing value in a needed column "
                     f"(lines {short_list([rows[r][0] for r in incomplete])})")
        kept = np.setdiff1d(kept, incomplete)
    return data[kept], kept


def _to_si(table: Table, data: np.ndarray, needed: list[str], declared: dict, col_of: dict, rows: list,
           kept: np.ndarray) -> np.ndarray:
    """The values converted to SI units; a value that overflows is refused (line and column named)."""
    factors = np.array([UNITS[quantity_of(n)][declared[n]] if declared.get(n) else 1.0 for n in needed])
    with np.errstate(over="ignore"):
        data = data * factors
    bad = np.argwhere(~np.isfinite(data))
    if bad.size:
        k, j = bad[0]
        i = col_of[needed[j]]
        line_no, cells = rows[kept[k]]
        raise InputError(f"value {cells[i]!r} in column {i + 1} '{table.raw_names[i]}' is too large: not a finite "
                         f"number in {si_unit(quantity_of(needed[j]))}", table.src, line_no, field=needed[j])
    return data


def _check_values(col: dict, sig_cols: list[str], line_of: list[int], src: str) -> None:
    """Refuse σ <= 0, a wind speed <= 0, a rotor speed < 0 and an air density <= 0 (line named)."""
    if sig_cols:
        sigma = np.column_stack([col[s] for s in sig_cols])
        bad = np.argwhere(~(sigma > 0))
        if bad.size:
            k, c = bad[0]
            raise InputError(f"noise sigma must be > 0, got {sigma[k, c]!r}", src, line_of[k], field=sig_cols[c])
    bad = np.flatnonzero(~(col["wind_speed"] > 0))
    if bad.size:
        raise InputError("wind speed must be > 0", src, line_of[bad[0]], field="wind_speed")
    for name, text in (("rotor_speed", "rotor speed must be >= 0"), ("air_density", "air density must be > 0")):
        if name in col:
            ok = col[name] >= 0 if name == "rotor_speed" else col[name] > 0
            bad = np.flatnonzero(~ok)
            if bad.size:
                raise InputError(f"{text}, got {col[name][bad[0]]:g}", src, line_of[bad[0]], field=name)


def _check_time_series_options(time_series, average_from, src: str) -> None:
    """Refuse an unknown ``time_series`` and an ``average_from`` without ``time_series='mean'``."""
    if time_series not in TIME_SERIES_MODES:
        raise InputError(f"time_series must be None, 'mean' or 'rows', got {time_series!r}", src, field="time_series")
    if average_from is None:
        return
    if time_series != "mean":
        raise InputError("average_from [s] applies with time_series='mean' only", src, field="average_from")
    try:
        ok = np.isfinite(float(average_from))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise InputError(f"average_from must be a finite time [s], got {average_from!r}", src, field="average_from")


def read_measurements(path: str | Path, channels: Sequence[str] | None = None, *,
                      drop_incomplete_rows: bool = False, allow_no_channels: bool = False,
                      time_series: str | None = None, average_from: float | None = None) -> Measurements:
    """Read a measurement table from CSV or OpenFAST text output (see the module docstring).

    Parameters
    ----------
    path : str or Path
        CSV file (UTF-8 with or without byte-order mark; comma, semicolon or tab), or OpenFAST
        text output (``.out``, recognised from its content; :mod:`calib.measurements.openfast_out`).
    channels : sequence of str, optional
        Channels to keep (default: every known channel column present).
    drop_incomplete_rows : bool
        Drop rows with a missing value (empty cell, ``nan``, ``NA`` ...) in a needed column
        (the conditions, the kept channels and their σ) and report the count in
        :attr:`Measurements.notes`. Default: refuse such a row, naming its line and column.
    allow_no_channels : bool
        Accept a table of conditions only (e.g. for predictions); default: refuse it.
    time_series : {None, "mean", "rows"}
        For OpenFAST output with more than one time row: None refuses it (calib expects one
        row per operating point), ``"mean"`` averages the rows into one operating point,
        ``"rows"`` reads every time row as a point. Other tables: noted and ignored.
    average_from : float, optional
        With ``time_series="mean"``: the time [s] the average starts at (the end of the
        start-up transient); default the first row.

    Returns
    -------
    Measurements
        Values in SI units; ``sigma`` set when every kept channel has a ``_sigma`` column;
        ``notes`` say what was detected, ignored, dropped or averaged.

    Raises
    ------
    InputError
        File not found, binary (an OpenFAST ``.outb`` among them) or not UTF-8/UTF-16 text;
        empty file; missing required column; unknown unit, or a unit both in the header and
        in the units row; missing value (unless dropped), non-numeric or non-finite cell (line
        and column named); σ <= 0; requested channel absent; an OpenFAST time series without
        ``time_series``.
    """
    path = Path(path)
    _check_time_series_options(time_series, average_from, str(path))
    text, notes = read_text(path)
    return measurements_from_text(text, path, notes, sha256_of(path), channels, drop_incomplete_rows,
                                   allow_no_channels, time_series, average_from)


def measurements_from_text(text: str, path: Path, notes: list, sha256: str, channels, drop_incomplete_rows: bool,
                            allow_no_channels: bool, time_series, average_from) -> Measurements:
    """The body of :func:`read_measurements` on text already read (``path`` names it in errors);
    :func:`calib.measurements.dataframe.read_dataframe` reads a DataFrame through it."""
    src = str(path)
    table = read_table(text, path, notes)
    _check_columns(table)
    if not table.lines:
        raise InputError("no data rows after the header", src, table.header_line)
    declared = _declared_units(table)
    rows = _split_rows(table)
    channels, sig_cols = _kept_channels(table, channels, allow_no_channels)
    needed = list(REQUIRED_CONDITIONS) + [f for f in CONDITION_DEFAULTS if f in set(table.names)] + channels + sig_cols
    index_of = {n: i for i, n in enumerate(table.names)}
    col_of = {n: index_of[n] for n in needed}
    times = {}
    if table.openfast is not None:
        rows, times, more = time_rows(rows, table.raw_names, time_series, average_from, src)
        notes += more
    elif time_series is not None:
        notes.append(f"time_series={time_series!r} ignored: the table is not OpenFAST time-series output")
    decimal_comma = table.delimiter in (";", "\t") and any(
        DECIMAL_COMMA.match(cells[i]) for _, cells in rows for i in col_of.values() if i < len(cells))
    if decimal_comma:
        notes.append("decimal comma: ',' read as the decimal separator")
    if table.openfast is None:
        notes += _ignored_column_notes(table, rows, decimal_comma)
    model_specific = _model_specific_channels(table, needed)
    if model_specific:
        notes.append("read as given, in the model's unit (no unit conversion for names calib does not know): "
                     + ", ".join(model_specific))
    no_unit = [n for n in needed if declared.get(n) is None and n not in model_specific]
    if no_unit:
        notes.append(f"no unit in the {'units row' if table.units_row else 'header'}, SI assumed: "
                     + ", ".join(f"{n} [{si_unit(quantity_of(n))}]" for n in no_unit))
    data, kept = _parse_values(table, rows, needed, col_of, decimal_comma, drop_incomplete_rows, notes)
    data = _to_si(table, data, needed, declared, col_of, rows, kept)
    line_of = [rows[k][0] for k in kept]
    col = {n: data[:, j] for j, n in enumerate(needed)}
    _check_values(col, sig_cols, line_of, src)
    metadata = {"units": declared, "delimiter": table.delimiter, "decimal_comma": decimal_comma,
                "units_row": table.units_row[0] if table.units_row else None,
                "format": "openfast" if table.openfast is not None else "csv"}
    if table.openfast is not None:
        metadata["openfast_channels"] = dict(table.openfast.read)
        if time_series == "mean" and len(line_of) > 1:
            t = np.array([times[ln] for ln in line_of])
            col, note = average(col, t, {n: si_unit(quantity_of(n)) for n in col})
            notes.append(note)
            metadata["time_window"], metadata["time_rows"] = (float(t[0]), float(t[-1])), int(t.size)
            line_of = line_of[:1]
    metadata["lines"] = tuple(line_of)
    cond = OperatingConditions(**{f: col.get(f, CONDITION_DEFAULTS.get(f)) for f in CONDITION_FIELDS})
    values = np.column_stack([col[c] for c in channels]) if channels else np.zeros((len(line_of), 0))
    sigma = np.column_stack([col[s] for s in sig_cols]) if sig_cols else None
    return Measurements(cond, tuple(channels), values, sigma, source=src, sha256=sha256,
                        metadata=metadata, notes=tuple(notes))
