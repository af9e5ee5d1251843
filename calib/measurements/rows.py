"""The data rows of a measurement table as numbers in SI units.

The row side of :func:`calib.measurements.reader.read_measurements`: the data lines split into
cells (:func:`split_rows`), the needed cells read as numbers, a row with a missing value refused
or dropped (:func:`parse_values`), the values converted to SI (:func:`to_si`) and the
conditions and σ checked (:func:`check_values`). A refusal names the file, the line and the
column.
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.measurements.cells import MISSING_CELLS, is_number_cell, short_list, split_line, to_float
from calib.measurements.table import Table
from calib.measurements.units import UNITS, quantity_of, si_unit


def _cells_error(table: Table, n_cells: int, line_no: int) -> InputError:
    """The error of a row whose cell count does not match the header (with the decimal-comma hint)."""
    hint = ("; numbers with a decimal comma need columns separated by ';' or tab"
            if table.delimiter == "," and n_cells > len(table.names) else "")
    return InputError(f"row has {n_cells} cells, header has {len(table.names)}{hint}", table.src, line_no)


def split_rows(table: Table) -> list[tuple[int, list[str]]]:
    """The data lines as (line number, stripped cells); a row longer than the header is refused.

    Parameters
    ----------
    table : Table

    Returns
    -------
    list of (int, list of str)

    Raises
    ------
    InputError
        A row with more cells than the header (line named).
    """
    rows = []
    for line_no, t in table.lines:
        cells = split_line(t, table.delimiter, table.src, line_no)
        if len(cells) > len(table.names):
            raise _cells_error(table, len(cells), line_no)
        rows.append((line_no, [c.strip() for c in cells]))
    return rows


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


def parse_values(table: Table, rows: list, needed: list[str], col_of: dict, decimal_comma: bool,
                 drop_incomplete_rows: bool, notes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The needed cells as numbers, shape (n_kept, n_needed), and the indices of the rows kept.

    A row with a missing value is refused, or dropped (``drop_incomplete_rows``, noted).

    Parameters
    ----------
    table : Table
    rows : list of (int, list of str)
        From :func:`split_rows`.
    needed : list of str
        Columns to read, in order.
    col_of : dict
        Column name -> cell index.
    decimal_comma : bool
        Whether a comma is the decimal separator.
    drop_incomplete_rows : bool
    notes : list of str
        Appended to when rows are dropped.

    Returns
    -------
    data : ndarray, shape (n_kept, n_needed)
        In the units of the file.
    kept : ndarray of int
        Indices into ``rows``.

    Raises
    ------
    InputError
        A missing (unless dropped), non-numeric, ambiguous or non-finite cell (line and column
        named); every row incomplete.
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


def to_si(table: Table, data: np.ndarray, needed: list[str], declared: dict, col_of: dict, rows: list,
          kept: np.ndarray) -> np.ndarray:
    """The values converted to SI units; a value that overflows is refused (line and column named).

    Parameters
    ----------
    table : Table
    data : ndarray, shape (n_kept, n_needed)
        From :func:`parse_values`.
    needed : list of str
    declared : dict
        Column -> declared unit (:func:`calib.measurements.columns.declared_units`).
    col_of : dict
        Column name -> cell index.
    rows : list of (int, list of str)
    kept : ndarray of int

    Returns
    -------
    ndarray, shape (n_kept, n_needed)
        In SI units of the contract (:data:`~calib.measurements.units.UNITS`).
    """
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


def check_values(col: dict, sig_cols: list[str], line_of: list[int], src: str) -> None:
    """Refuse σ <= 0, a wind speed <= 0, a rotor speed < 0 and an air density <= 0 (line named).

    Parameters
    ----------
    col : dict
        Column name -> values in SI units, shape (n_points,).
    sig_cols : list of str
        The σ columns.
    line_of : list of int
        File line of each point.
    src : str
        The file, for the message.

    Raises
    ------
    InputError
        The first value out of its range (line and column named).
    """
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
