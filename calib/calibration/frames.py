"""pandas out: predictions and results as DataFrames (measurements are read from one by
:func:`calib.measurements.read_dataframe`).

Field data and simulation outputs usually live in pandas. pandas is an optional extra
(``pip install 'calib[pandas]'``): the calibration itself needs only numpy, and a DataFrame is
a convenience at its edges, so the core stays light.

- :func:`prediction_frame`: a :class:`calib.calibration.prediction.Prediction` with its conditions, one row per
  point, units in the column names;
- :func:`parameters_frame`: a calibration's parameters with their estimates, σ, priors and verdicts;
- :func:`points_frame`: per operating point the measured, nominal and calibrated outputs and the
  whitened residuals.
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.types import CONDITION_FIELDS, Status

CONDITION_UNITS = {"wind_speed": "m/s", "rotor_speed": "rpm", "pitch": "deg", "air_density": "kg/m^3", "yaw": "deg"}


def require_pandas():
    """The pandas module, or an :class:`~calib.errors.InputError` saying how to install it."""
    try:
        import pandas as pd
    except ImportError as exc:     # an optional extra
        raise InputError("pandas is needed for DataFrames: pip install 'calib[pandas]' (or pandas>=2.0)",
                         "calib.calibration.frames") from exc
    return pd


def prediction_frame(conditions, prediction):
    """One row per predicted point: its conditions, each channel with its 1-σ and interval, the
    status and the envelope flag.

    Parameters
    ----------
    conditions : OperatingConditions
        The conditions the prediction was made at.
    prediction : calib.calibration.prediction.Prediction

    Returns
    -------
    pandas.DataFrame
        Columns ``wind_speed [m/s]`` … ``yaw [deg]``, then per channel ``power [W]``,
        ``power_std [W]``, ``power_lower [W]``, ``power_upper [W]``, ``power_discrepancy_std [W]``
        (the model discrepancy's part of the 1-σ), ``power_field_std [W]`` (the part from the correction
        field between and beyond the nodes); ``status`` (name),
        ``envelope`` (``inside``/``outside``) and ``outside_because``.
    """
    pd = require_pandas()
    cols = {f"{f} [{CONDITION_UNITS[f]}]": np.broadcast_to(getattr(conditions, f), prediction.values.shape[:1])
            for f in CONDITION_FIELDS}
    for j, (c, u) in enumerate(zip(prediction.channels, prediction.units)):
        cols[f"{c} [{u}]"] = prediction.values[:, j]
        cols[f"{c}_std [{u}]"] = prediction.std[:, j]
        cols[f"{c}_lower [{u}]"] = prediction.lower[:, j]
        cols[f"{c}_upper [{u}]"] = prediction.upper[:, j]
        if prediction.discrepancy_std is not None:
            cols[f"{c}_discrepancy_std [{u}]"] = prediction.discrepancy_std[:, j]
        if prediction.field_std is not None:
            cols[f"{c}_field_std [{u}]"] = prediction.field_std[:, j]
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
    result : calib.calibration.result.CalibrationResult

    Returns
    -------
    pandas.DataFrame
        Indexed by parameter name; columns ``kind``, ``unit``, ``nominal``, ``value``, ``std``,
        ``prior_std``, ``lower``, ``upper``, ``verdict``, ``shared_information``, ``note``.
    """
    pd = require_pandas()
    by_name = {v["name"]: v for v in result.identifiability.verdicts}
    rows = []
    for j, q in enumerate(result.parameters):
        v = by_name.get(q["name"], {})
        kind = q.get("kind", "")
        rows.append({"name": q["name"], "kind": str(getattr(kind, "value", kind)), "unit": q.get("unit", ""),
                     "nominal": float(result.estimate.p_nominal[j]), "value": float(result.estimate.p_hat[j]),
                     "std": float(result.uncertainty.std_p[j]), "prior_std": float(result.uncertainty.prior_std[j]),
                     "lower": float(result.estimate.lower[j]), "upper": float(result.estimate.upper[j]),
                     "verdict": v.get("verdict", ""), "shared_information": v.get("shared_information", np.nan),
                     "note": v.get("note", "")})
    return pd.DataFrame(rows).set_index("name")


def points_frame(result):
    """One row per calibration point: its conditions, and per channel the measurement, the
    nominal and the calibrated model, and the whitened residual after calibration.

    Parameters
    ----------
    result : calib.calibration.result.CalibrationResult

    Returns
    -------
    pandas.DataFrame
        Columns ``wind_speed [m/s]`` … ``yaw [deg]``, ``tip_speed_ratio [-]`` (when the rotor radius is
        known), then per channel ``power [W]``, ``power_nominal [W]``, ``power_calibrated [W]``,
        ``power_residual [-]``; ``status``.
    """
    pd = require_pandas()
    n = result.fit.measured.shape[0]
    cols = {f"{f} [{CONDITION_UNITS[f]}]": np.broadcast_to(np.asarray(result.conditions[f], float), (n,))
            for f in CONDITION_FIELDS if f in result.conditions}
    if result.provenance.rotor_radius:
        cols["tip_speed_ratio [-]"] = result.tip_speed_ratio()
    for j, (c, u) in enumerate(zip(result.channels, result.channel_units)):
        cols[f"{c} [{u}]"] = result.fit.measured[:, j]
        cols[f"{c}_nominal [{u}]"] = result.fit.model_before[:, j]
        cols[f"{c}_calibrated [{u}]"] = result.fit.model_after[:, j]
        cols[f"{c}_residual [-]"] = (result.fit.measured[:, j] - result.fit.model_after[:, j]) / result.fit.sigma[:, j]
    cols["status"] = [Status(int(s)).name for s in result.fit.status_after]
    return pd.DataFrame(cols)
