"""Measurement tables: CSV and OpenFAST-output reading with units, noise models, synthetic measurements.

A measurement table holds, per operating point k, the conditions u_k and the measured
outputs z_k of some model channels, optionally with their 1-σ noise.

:func:`read_measurements` lives here; the file is split into header, units row and data lines
by :mod:`calib.measurements.table`, its cells are read by :mod:`calib.measurements.cells`, its
columns and their units checked by :mod:`calib.measurements.columns` and its rows read as
numbers in SI units by :mod:`calib.measurements.rows`.

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
- noise: ``<channel>_sigma``, the 1-σ noise of that channel, in the same unit;
- condition uncertainty: ``wind_speed_sigma``, ``rotor_speed_sigma``, ``pitch_sigma``, ``air_density_sigma``, the 1-σ
  of a measured condition (>= 0), in the condition's units (read into
  :attr:`Measurements.condition_sigma` for the errors-in-variables estimator).

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

from pathlib import Path
from typing import Sequence

import numpy as np

from calib.errors import InputError
from calib.measurements.cells import DECIMAL_COMMA
from calib.measurements.columns import (check_columns, declared_units, ignored_column_notes, kept_channels,
                                        model_specific_channels)
from calib.measurements.data import Measurements, sha256_of
from calib.measurements.openfast_out import TIME_SERIES_MODES, average, time_rows
from calib.measurements.rows import check_values, parse_values, split_rows, to_si
from calib.measurements.table import read_table, read_text
from calib.measurements.units import REQUIRED_CONDITIONS, quantity_of, si_unit
from calib.types import CONDITION_DEFAULTS, CONDITION_FIELDS, OperatingConditions


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
    check_columns(table)
    if not table.lines:
        raise InputError("no data rows after the header", src, table.header_line)
    declared = declared_units(table)
    rows = split_rows(table)
    channels, sig_cols = kept_channels(table, channels, allow_no_channels)
    cond_sig_cols = [f"{c}_sigma" for c in ("wind_speed", "rotor_speed", "pitch", "air_density")
                     if f"{c}_sigma" in table.names]
    needed = list(REQUIRED_CONDITIONS) + [f for f in CONDITION_DEFAULTS if f in set(table.names)] + channels + sig_cols
    needed += cond_sig_cols
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
        notes += ignored_column_notes(table, rows, decimal_comma)
    model_specific = model_specific_channels(table, needed)
    if model_specific:
        notes.append("read as given, in the model's unit (no unit conversion for names calib does not know): "
                     + ", ".join(model_specific))
    no_unit = [n for n in needed if declared.get(n) is None and n not in model_specific]
    if no_unit:
        notes.append(f"no unit in the {'units row' if table.units_row else 'header'}, SI assumed: "
                     + ", ".join(f"{n} [{si_unit(quantity_of(n))}]" for n in no_unit))
    data, kept = parse_values(table, rows, needed, col_of, decimal_comma, drop_incomplete_rows, notes)
    data = to_si(table, data, needed, declared, col_of, rows, kept)
    line_of = [rows[k][0] for k in kept]
    col = {n: data[:, j] for j, n in enumerate(needed)}
    check_values(col, sig_cols, line_of, src)
    cond_sigma = condition_sigma_columns(col, cond_sig_cols, line_of, table, notes)
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
                        metadata=metadata, notes=tuple(notes), condition_sigma=cond_sigma)


def condition_sigma_columns(col: dict, columns: list[str], line_of: list[int], table, notes: list) -> dict | None:
    """The condition σ columns (``wind_speed_sigma`` ...) checked, as :attr:`Measurements.condition_sigma`;
    a note says which were read. A negative or non-finite σ is refused, naming line and column.

    Parameters
    ----------
    col : dict
        Column name -> values in SI units of the contract, shape (n_points,).
    columns : list of str
        The condition σ columns present.
    line_of : list of int
        File line of each point.
    table : Table
        For the file name and the column's position and header.
    notes : list of str
        Appended to.

    Returns
    -------
    dict or None
        Condition -> σ per point [m/s, rpm, deg, kg/m^3]; None without such columns.

    Raises
    ------
    InputError
        The first σ < 0 (a σ of 0 states an exact condition).
    """
    for name in columns:
        bad = np.flatnonzero(~(col[name] >= 0))
        if bad.size:
            i = table.names.index(name)
            raise InputError(f"condition sigma in column {i + 1} '{table.raw_names[i]}' must be >= 0 "
                             f"({si_unit(quantity_of(name))}; 0 for an exact condition), got {col[name][bad[0]]:g}",
                             table.src, line_of[bad[0]], field=name)
    if not columns:
        return None
    notes.append("condition uncertainty read: " + ", ".join(f"{c} [{si_unit(quantity_of(c))}]" for c in columns))
    return {c[:-6]: col[c] for c in columns}
