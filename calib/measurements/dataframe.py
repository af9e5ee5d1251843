"""Measurements from a pandas DataFrame (:func:`read_dataframe`), read and checked exactly as
a CSV table by :func:`calib.measurements.read_measurements`: units from the column names
such as ``"power [kW]"`` or from ``units=``, σ columns, missing values, unit conversion to SI;
errors name the DataFrame's row (by position, from 0) and column. pandas is an optional extra
(``pip install 'calib[pandas]'``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
from pathlib import Path
from typing import Mapping, Sequence

from calib.calibration.frames import require_pandas
from calib.errors import InputError
from calib.measurements.data import Measurements
from calib.measurements.reader import measurements_from_text


def read_dataframe(df, channels: Sequence[str] | None = None, *, units: Mapping[str, str] | None = None,
                   source: str = "DataFrame", drop_incomplete_rows: bool = False,
                   allow_no_channels: bool = False) -> Measurements:
    """Measurements from a DataFrame, read and checked exactly as a CSV table.

    Parameters
    ----------
    df : pandas.DataFrame
        One row per operating point. Columns as in a CSV table: ``wind_speed``, ``rotor_speed``,
        ``pitch`` (required), ``air_density``, ``yaw``, channels and ``<channel>_sigma``; a unit in
        the name (``"power [kW]"``) or in ``units``. Other columns are noted and ignored.
    channels : sequence of str, optional
        Channels to keep (default: every known channel column present).
    units : mapping column -> unit, optional
        Units of columns whose names carry none (e.g. ``{"power": "kW", "thrust": "kN"}``).
    source : str
        Name in messages and in the result's provenance.
    drop_incomplete_rows, allow_no_channels : bool
        As in :func:`calib.measurements.read_measurements`.

    Returns
    -------
    Measurements
        In SI units. Errors name the row by its position in ``df`` (from 0) and the column.
    """
    pd = require_pandas()
    if not isinstance(df, pd.DataFrame):
        raise InputError(f"expected a pandas DataFrame, got {type(df).__name__}", source)
    units = dict(units or {})
    names = [str(c) for c in df.columns]
    unknown = [c for c in units if c not in names]
    if unknown:
        raise InputError(f"units given for column(s) not in the DataFrame: {', '.join(unknown)}; columns: "
                         f"{', '.join(names)}", source, field="units")
    for c in names:
        if c in units and "[" in c:
            raise InputError(f"column {c!r} states its unit in its name and in units= ({units[c]!r}); state it once",
                             source, field=c)
    header = [f"{c} [{units[c]}]" if c in units else c for c in names]
    frame = df.copy()
    frame.columns = header
    text = frame.to_csv(index=False, lineterminator="\n", na_rep="nan")
    digest = hashlib.sha256(text.encode("utf-8")).hexdigest()
    try:
        meas = measurements_from_text(text, Path(source), [], digest, channels, drop_incomplete_rows,
                                       allow_no_channels, None, None)
    except InputError as exc:       # the CSV text's line L is the DataFrame's row L − 2 (by position)
        if exc.line is None or exc.line < 2:
            raise
        raise InputError(f"row {exc.line - 2} (by position, from 0): {exc.message}", source,
                         field=exc.field) from None
    # the notes name the CSV text's lines; the user's rows are those lines − 2 (by position, from 0)
    return dataclasses.replace(meas, notes=tuple(_LINES.sub(_as_rows, n) for n in meas.notes))


_LINES = re.compile(r"\(lines ([\d, ]+)((?: \.\.\. \(\d+ in all\))?)\)")


def _as_rows(m) -> str:
    rows = ", ".join(str(int(v) - 2) for v in m.group(1).split(","))
    return f"(rows {rows}{m.group(2)}, by position from 0)"
