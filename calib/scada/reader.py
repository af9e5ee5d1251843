"""Read SCADA exports of 10-minute statistics: one row per turbine and period, statistics per signal.

:func:`read_scada` reads a CSV export (comma, semicolon or tab; UTF-8 or UTF-16 with byte-order
mark) whose columns are a time stamp, optionally a turbine name, and statistics of signals named
as in :data:`calib.scada.mapping.COLUMN_MAP` (extensible). Values are converted to SI (temperature
in K, pressure in Pa, power in W, angles in deg, rotor speed in rpm); what cannot be read is an
:class:`~calib.errors.InputError` naming the file, the line and the column, and what is merely
unusable is a counted flag, never a silent drop:

- a missing value in a signal's mean: flag ``missing``;
- a second record of a turbine at the same time stamp: flag ``duplicate_stamp`` (the first one
  kept), or an error with ``duplicates="error"``;
- a gap in a turbine's time series (a step longer than ``period``): counted per turbine in
  :attr:`ScadaRecords.gaps`, or an error with ``gaps="error"``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from datetime import datetime, timezone
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from calib.errors import InputError
from calib.measurements.cells import MISSING_CELLS, detect_delimiter, did_you_mean, parse_header, short_list, split_line
from calib.measurements.table import read_text
from calib.scada.mapping import SIGNALS, TIME_COLUMNS, TURBINE_COLUMNS, canonical_unit, column_map

#: the signals a power-curve analysis needs (their means)
REQUIRED_SIGNALS = ("wind_speed", "power")


@dataclass(frozen=True)
class ScadaRecords:
    """10-minute records of one or more turbines, sorted by turbine and time, values in SI.

    Attributes
    ----------
    source : str
        The file read.
    turbine : ndarray of str, shape (n_records,)
    time : ndarray of float, shape (n_records,)
        Start of the period [s since 1970-01-01 UTC].
    line : ndarray of int, shape (n_records,)
        Line of each record in the file.
    values : dict
        ``(signal, statistic)`` -> ndarray (n_records,) in SI (NaN where missing).
    columns : dict
        ``(signal, statistic)`` -> the export's column name.
    flags : dict
        Flags set while reading (``missing``, ``duplicate_stamp``) -> bool ndarray (n_records,).
    gaps : dict
        Turbine -> number of 10-minute periods missing from its time series.
    notes : tuple of str
        What was detected, converted and ignored.
    """

    source: str
    turbine: np.ndarray
    time: np.ndarray
    line: np.ndarray
    values: dict
    columns: dict
    flags: dict = field(default_factory=dict)
    gaps: dict = field(default_factory=dict)
    notes: tuple = ()

    def __len__(self) -> int:
        return int(self.time.size)

    def has(self, signal: str, statistic: str = "mean") -> bool:
        return (signal, statistic) in self.values

    def get(self, signal: str, statistic: str = "mean") -> np.ndarray:
        """The ``statistic`` of ``signal`` per record [SI]; InputError if the export has no such column."""
        try:
            return self.values[(signal, statistic)]
        except KeyError:
            raise InputError(f"no {statistic} of {signal} in the export; present: "
                             f"{', '.join(f'{s}_{t}' for s, t in self.values)}", self.source,
                             field=f"{signal}_{statistic}") from None

    @property
    def turbines(self) -> list[str]:
        return list(dict.fromkeys(self.turbine.tolist()))

    def select(self, mask: np.ndarray) -> "ScadaRecords":
        """The records where ``mask`` is true (flags and values cut alike)."""
        mask = np.asarray(mask, bool)
        return replace(self, turbine=self.turbine[mask], time=self.time[mask], line=self.line[mask],
                       values={k: v[mask] for k, v in self.values.items()},
                       flags={k: v[mask] for k, v in self.flags.items()})


def _parse_time(cell: str, src: str, line: int, column: str) -> tuple[float, bool]:
    """(seconds since epoch UTC, whether the stamp carried an offset)."""
    text = cell.strip().replace("Z", "+00:00")
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise InputError(f"time stamp {cell!r} is not ISO 8601 (e.g. 2014-01-01T01:00:00+01:00)", src, line,
                         field=column) from None
    if t.tzinfo is None:
        return t.replace(tzinfo=timezone.utc).timestamp(), False
    return t.timestamp(), True


def _check_unit(name: str, signal: str, stat: str, unit: str, values: np.ndarray, src: str, line: int) -> None:
    """Refuse a mean column (``values`` as the export writes them, in ``unit``) whose median lies outside the signal's plausible range, saying which unit fits."""
    if stat != "mean":
        return
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return
    raw = float(np.median(finite))
    lo, hi = SIGNALS[signal].plausible
    factor, offset = SIGNALS[signal].units[unit]
    if lo <= raw * factor + offset <= hi:
        return
    fits = [u for u, (f, o) in SIGNALS[signal].units.items() if lo <= raw * f + o <= hi]
    hint = f"; the values look like {' or '.join(fits)}: give the unit in the header, e.g. '{name} [{fits[0]}]'" \
        if fits else ""
    raise InputError(f"{signal} read in {unit} has median {raw:.6g} {unit}, outside the plausible "
                     f"{lo:g}..{hi:g} {SIGNALS[signal].si_unit}{hint}", src, line, field=name)


def read_scada(path: str | Path, *, mapping: Mapping[str, tuple] | None = None,
               units: Mapping[str, str] | None = None, required: Sequence[str] = REQUIRED_SIGNALS,
               ignore: Sequence[str] = (), unknown: str = "error", turbine: str | None = None,
               period: float = 600.0, duplicates: str = "flag", gaps: str = "count") -> ScadaRecords:
    """Read a SCADA export of 10-minute statistics (see the module docstring).

    Parameters
    ----------
    path : str or Path
        CSV export: a time-stamp column (ISO 8601; with a UTC offset, or read as UTC with a note),
        optionally a turbine column, and signal statistics (``Ws_avg``, ``P_std`` ...).
    mapping : dict, optional
        Further column names: ``{"name": (signal, statistic[, unit])}``, added to
        :data:`~calib.scada.mapping.COLUMN_MAP` (see :func:`~calib.scada.mapping.column_map`).
    units : dict, optional
        Column name -> unit, overriding the mapping's unit for columns whose header gives none.
    required : sequence of str
        Signals whose mean must be present (default wind speed and power).
    ignore : sequence of str
        Column names to skip without a word; any other column the mapping does not know is refused
        (``unknown="error"``, default) or skipped with a note (``unknown="note"``).
    turbine : str, optional
        Keep this turbine only (an export with a turbine column).
    period : float
        Record period [s] (600: 10 minutes); a longer step is a gap.
    duplicates : {"flag", "error"}
        A second record of a turbine at one time stamp: flagged ``duplicate_stamp`` or refused.
    gaps : {"count", "error"}
        A gap in a turbine's time series: counted in :attr:`ScadaRecords.gaps` or refused.

    Returns
    -------
    ScadaRecords

    Raises
    ------
    InputError
        File unreadable; no time-stamp column; a required signal absent; an unknown column; an
        unknown unit; a column twice; a non-numeric cell; a negative standard deviation; a mean whose
        median is implausible in its unit (a temperature in K read as °C, a pressure in Pa read as
        hPa, a density in g/m³); a duplicate stamp or a gap when asked to refuse them. Each names
        the file, the line and the column.
    """
    path = Path(path)
    src = str(path)
    for name, value, allowed in (("duplicates", duplicates, ("flag", "error")), ("gaps", gaps, ("count", "error")),
                                 ("unknown", unknown, ("error", "note"))):
        if value not in allowed:
            raise InputError(f"{name} must be {' or '.join(map(repr, allowed))}, got {value!r}", src, field=name)
    text, notes = read_text(path)
    lines = [(i + 1, s) for i, s in enumerate(text.splitlines()) if s.strip() and not s.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty file: expected a header and one row per 10 minutes", src)
    header = _read_header(lines, src, column_map(mapping, src), units, required, ignore, unknown, notes)
    line, time, turbines, arr = _read_rows(lines[1:], header, src, turbine, notes)
    values = {}
    for j, key in enumerate(header.signals):
        _, raw, unit = header.signals[key]
        _check_unit(raw, key[0], key[1], unit, arr[:, j], src, header.line)
        factor, offset = SIGNALS[key[0]].units[unit]
        values[key] = arr[:, j] * factor + (offset if key[1] != "std" else 0.0)
        if unit != SIGNALS[key[0]].si_unit:
            notes.append(f"{raw}: {unit} converted to {SIGNALS[key[0]].si_unit}")
    order = np.lexsort((time, turbines.astype(str)))   # stable: the first line of a stamp stays first
    if np.any(order != np.arange(order.size)):
        notes.append("records sorted by turbine and time stamp")
    turbines, time, line = turbines[order], time[order], line[order]
    values = {k: v[order] for k, v in values.items()}
    missing = np.zeros(time.size, bool)
    for (sig, stat), v in values.items():
        if stat == "mean":
            missing |= ~np.isfinite(v)
    duplicate, gap_count = _time_flags(turbines, time, line, period, duplicates, gaps, src, header.time[1])
    flags = {"missing": missing, "duplicate_stamp": duplicate}
    return ScadaRecords(src, turbines, time, line, values, {k: v[1] for k, v in header.signals.items()}, flags,
                        gap_count, tuple(notes))


@dataclass(frozen=True)
class _Header:
    line: int
    delimiter: str
    n_cols: int
    time: tuple
    turbine: tuple | None
    signals: dict          # (signal, statistic) -> (column index, header text, unit)


def _signal_unit(raw, name, head_unit, entry, units, src, line) -> str:
    """The unit of a signal column: the header's, else ``units``', else the mapping's."""
    signal, _, unit = entry
    given = head_unit or (units or {}).get(raw) or (units or {}).get(name)
    if given is None:
        return unit
    unit = canonical_unit(signal, given)
    if unit is None:
        raise InputError(f"unit {given!r} is not a unit of {signal}; accepted: {', '.join(SIGNALS[signal].units)}",
                         src, line, field=raw)
    return unit


def _read_header(lines, src, cmap, units, required, ignore, unknown, notes) -> _Header:
    """The time, turbine and signal columns of the header line; refuses unknown and duplicate columns and
    a missing time stamp or required signal."""
    header_line, header = lines[0]
    delimiter = detect_delimiter(header, [s for _, s in lines[1:6]]) or ","
    raw_names = split_line(header, delimiter, src, header_line)
    ignored = {n.strip().lower() for n in ignore}
    time_col = turbine_col = None
    signal_cols, skipped = {}, []
    for i, raw in enumerate(raw_names):
        name, head_unit = parse_header(raw, i + 1)
        if raw.strip().lower() in ignored or name in ignored:
            continue
        if name in TIME_COLUMNS and time_col is None:
            time_col = (i, raw)
        elif name in TURBINE_COLUMNS and turbine_col is None:
            turbine_col = (i, raw)
        elif name not in cmap:
            if unknown == "error":
                raise InputError(f"unknown column {raw!r}{did_you_mean(name, list(cmap))}; name it in mapping= "
                                 f"({{'{raw}': (signal, statistic, unit)}}) or in ignore=", src, header_line,
                                 field=raw)
            skipped.append(raw)
        else:
            key = cmap[name][:2]
            if key in signal_cols:
                raise InputError(f"{key[0]} {key[1]} given twice: columns {signal_cols[key][1]!r} and {raw!r}",
                                 src, header_line, field=raw)
            signal_cols[key] = (i, raw, _signal_unit(raw, name, head_unit, cmap[name], units, src, header_line))
    if time_col is None:
        raise InputError(f"no time-stamp column (one of {', '.join(TIME_COLUMNS)}); columns: "
                         f"{short_list(raw_names, 30)}", src, header_line)
    for sig in required:
        if (sig, "mean") not in signal_cols:
            names = [k for k, v in cmap.items() if v[:2] == (sig, "mean")]
            raise InputError(f"missing required signal '{sig}' (its mean, e.g. column {short_list(names, 4)}); "
                             f"columns present: {short_list(raw_names, 30)}", src, header_line, field=sig)
    if skipped:
        notes.append(f"columns not read (unknown=note): {short_list(skipped, 20)}")
    return _Header(header_line, delimiter, len(raw_names), time_col, turbine_col, signal_cols)


def _cell_value(cell: str, is_std: bool, src: str, line: int, column: str) -> float:
    cell = cell.strip()
    if cell.lower() in MISSING_CELLS:
        return np.nan
    try:
        v = float(cell)
    except ValueError:
        raise InputError(f"{cell!r} is not a number", src, line, field=column) from None
    if not np.isfinite(v):
        return np.nan
    if is_std and v < 0:
        raise InputError(f"negative standard deviation {v:g}: a σ is >= 0", src, line, field=column)
    return v


def _read_rows(lines, header: _Header, src: str, turbine: str | None, notes: list):
    """(line, time, turbine, values as written (n_records, n_signals)) of the data lines."""
    rows_line, rows_time, rows_turbine, data, offsets = [], [], [], [], 0
    columns = [(i, raw, key[1] == "std") for key, (i, raw, _) in header.signals.items()]
    for ln, s in lines:
        cells = split_line(s, header.delimiter, src, ln)
        cells += [""] * (header.n_cols - len(cells))
        name = cells[header.turbine[0]].strip() if header.turbine else ""
        if turbine is not None and name != turbine:
            continue
        t, has_offset = _parse_time(cells[header.time[0]], src, ln, header.time[1])
        offsets += has_offset
        data.append([_cell_value(cells[i], is_std, src, ln, raw) for i, raw, is_std in columns])
        rows_line.append(ln)
        rows_time.append(t)
        rows_turbine.append(name)
    if not data:
        what = f" of turbine {turbine!r}" if turbine is not None else ""
        raise InputError(f"no data rows{what} after the header", src, header.line)
    if offsets < len(data):
        notes.append(f"{len(data) - offsets} time stamps without a UTC offset read as UTC")
    return (np.array(rows_line), np.array(rows_time), np.array(rows_turbine, dtype=object),
            np.array(data, float).reshape(len(data), len(columns)))


def _time_flags(turbines, time, line, period, duplicates, gaps, src, time_column):
    """Per record: a later record of a stamp already seen (``duplicate_stamp``); per turbine: the
    periods missing. Records sorted by turbine and time."""
    duplicate = np.zeros(time.size, bool)
    gap_count = {}
    for name in dict.fromkeys(turbines.tolist()):
        idx = np.flatnonzero(turbines == name)
        step = np.diff(time[idx])
        dup = np.concatenate([[False], step == 0])
        of = f" of turbine {name}" if name else ""
        if dup.any() and duplicates == "error":
            k = idx[np.flatnonzero(dup)[0]]
            raise InputError(f"duplicate time stamp {datetime.fromtimestamp(time[k], timezone.utc).isoformat()}{of} "
                             "(also on an earlier line)", src, int(line[k]), field=time_column)
        duplicate[idx] = dup
        long = step > period * 1.0001
        gap_count[name] = int(np.sum(np.round(step[long] / period) - 1))
        if long.any() and gaps == "error":
            k = idx[np.flatnonzero(long)[0] + 1]
            raise InputError(f"gap of {step[long][0] / period:g} periods before this record{of}", src, int(line[k]),
                             field=time_column)
    return duplicate, gap_count
