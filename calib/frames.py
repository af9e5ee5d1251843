"""pandas in and out: measurements from a DataFrame, predictions and results as DataFrames.

Field data and simulation outputs usually live in pandas. pandas is an optional extra
(``pip install 'calib[pandas]'``): the calibration itself needs only numpy, and a DataFrame is
a convenience at its edges, so the core stays light.

- :func:`measurements_from_dataframe`: the same reader and the same checks as a CSV file (units
  from the column names such as ``"power [kW]"`` or from ``units=``, σ columns, missing values,
  unit conversion to SI), errors naming the DataFrame's row and column;
- :func:`prediction_frame`: a :class:`calib.result.Prediction` with its conditions, one row per
  point, units in the column names;
- :func:`parameters_frame`: a calibration's parameters with their estimates, σ, priors and verdicts;
- :func:`points_frame`: per operating point the measured, nominal and calibrated outputs and the
  whitened residuals.
"""

from __future__ import annotations

import dataclasses
import re
import hashlib
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from calib.errors import InputError
from calib.measurements import Measurements
from calib.measurements.reader import _measurements_from_text
from calib.types import CONDITION_FIELDS, Status

CONDITION_UNITS = {"wind_speed": "m/s", "rotor_speed": "rpm", "pitch": "deg", "air_density": "kg/m^3", "yaw": "deg"}


def _pandas():
    try:
        import pandas as pd
    except ImportError as exc:     # an optional extra
        raise InputError("pandas is needed for DataFrames: pip install 'calib[pandas]' (or pandas>=2.0)",
                         "calib.frames") from exc
    return pd


def measurements_from_dataframe(df, channels: Sequence[str] | None = None, *, units: Mapping[str, str] | None = None,
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
    pd = _pandas()
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
        meas = _measurements_from_text(text, Path(source), [], digest, channels, drop_incomplete_rows,
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


def prediction_frame(conditions, prediction):
    """One row per predicted point: its conditions, each channel with its 1-σ and interval, the
    status and the envelope flag.

    Parameters
    ----------
    conditions : OperatingConditions
        The conditions the prediction was made at.
    prediction : calib.result.Prediction

    Returns
    -------
    pandas.DataFrame
        Columns ``wind_speed [m/s]`` … ``yaw [deg]``, then per channel ``power [W]``,
        ``power_std [W]``, ``power_lower [W]``, ``power_upper [W]``; ``status`` (name),
        ``envelope`` (``inside``/``outside``) and ``outside_because``.
    """
    pd = _pandas()
    cols = {f"{f} [{CONDITION_UNITS[f]}]": np.broadcast_to(getattr(conditions, f), prediction.values.shape[:1])
            for f in CONDITION_FIELDS}
    for j, (c, u) in enumerate(zip(prediction.channels, prediction.units)):
        cols[f"{c} [{u}]"] = prediction.values[:, j]
        cols[f"{c}_std [{u}]"] = prediction.std[:, j]
        cols[f"{c}_lower [{u}]"] = prediction.lower[:, j]
        cols[f"{c}_upper [{u}]"] = prediction.upper[:, j]
    cols["status"] = [Status(int(s)).name for s in prediction.status]
    why = list(prediction.envelope) if prediction.envelope else [""] * prediction.values.shape[0]
    cols["envelope"] = ["outside" if w else "inside" for w in why]
    cols["outside_because"] = why
    return pd.DataFrame(cols)


def parameters_frame(result):
    """One row per parameter of a calibration: what it is, its estimate and σ, its prior and
    bounds, and the verdict (with how much information it shares with the others).

    Parameters
    ----------
    result : calib.result.CalibrationResult

    Returns
    -------
    pandas.DataFrame
        Indexed by parameter name; columns ``kind``, ``unit``, ``nominal``, ``value``, ``std``,
        ``prior_std``, ``lower``, ``upper``, ``verdict``, ``shared_information``, ``note``.
    """
    pd = _pandas()
    by_name = {v["name"]: v for v in result.verdicts}
    rows = []
    for j, q in enumerate(result.parameters):
        v = by_name.get(q["name"], {})
        kind = q.get("kind", "")
        rows.append({"name": q["name"], "kind": str(getattr(kind, "value", kind)), "unit": q.get("unit", ""),
                     "nominal": float(result.p_nominal[j]), "value": float(result.p_hat[j]),
                     "std": float(result.std_p[j]), "prior_std": float(result.prior_std[j]),
                     "lower": float(result.lower[j]), "upper": float(result.upper[j]),
                     "verdict": v.get("verdict", ""), "shared_information": v.get("shared_information", np.nan),
                     "note": v.get("note", "")})
    return pd.DataFrame(rows).set_index("name")


def points_frame(result):
    """One row per calibration point: its conditions, and per channel the measurement, the
    nominal and the calibrated model, and the whitened residual after calibration.

    Parameters
    ----------
    result : calib.result.CalibrationResult

    Returns
    -------
    pandas.DataFrame
        Columns ``wind_speed [m/s]`` … ``yaw [deg]``, ``tip_speed_ratio [-]`` (when the rotor radius is
        known), then per channel ``power [W]``, ``power_nominal [W]``, ``power_calibrated [W]``,
        ``power_residual [-]``; ``status``.
    """
    pd = _pandas()
    n = result.measured.shape[0]
    cols = {f"{f} [{CONDITION_UNITS[f]}]": np.broadcast_to(np.asarray(result.conditions[f], float), (n,))
            for f in CONDITION_FIELDS if f in result.conditions}
    if result.rotor_radius:
        cols["tip_speed_ratio [-]"] = result.tip_speed_ratio()
    for j, (c, u) in enumerate(zip(result.channels, result.channel_units)):
        cols[f"{c} [{u}]"] = result.measured[:, j]
        cols[f"{c}_nominal [{u}]"] = result.model_before[:, j]
        cols[f"{c}_calibrated [{u}]"] = result.model_after[:, j]
        cols[f"{c}_residual [-]"] = (result.measured[:, j] - result.model_after[:, j]) / result.sigma[:, j]
    cols["status"] = [Status(int(s)).name for s in result.status_after]
    return pd.DataFrame(cols)
