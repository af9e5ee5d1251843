"""``calib predict RESULT_DIR --data FILE.csv --out PRED.csv``: a calibrated model at new conditions.

The result rebuilds its model from the spec it recorded, evaluates it at the conditions of
FILE.csv and writes, next to the conditions, for each channel of the result
``<channel>``, ``<channel>_lower`` and ``<channel>_upper`` (the 95 % interval of the model
output, :meth:`calib.result.CalibrationResult.predict`) in SI units, and a ``status``
column. When FILE.csv also holds measured channels, χ²/dof of measured against predicted is
printed per channel and overall, with σ² = σ_meas² + σ_pred² (σ_meas from the ``_sigma``
columns, else the noise the calibration used).
"""

from __future__ import annotations

import csv
import os
import tempfile
from pathlib import Path

import numpy as np

from calib.measurements import read_measurements
from calib.result import Prediction, load_result
from calib.types import CONDITION_FIELDS, Status


def write_prediction_csv(path: str | Path, conditions: dict, prediction: Prediction, units: dict) -> Path:
    """Write conditions and predictions with their intervals (atomically)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cond_units = {"wind_speed": "m/s", "rotor_speed": "rpm", "pitch": "deg", "air_density": "kg/m^3", "yaw": "deg"}
    header = [f"{c} [{cond_units[c]}]" for c in CONDITION_FIELDS]
    for c, u in zip(prediction.channels, prediction.units):
        header += [f"{c} [{u}]", f"{c}_lower [{u}]", f"{c}_upper [{u}]"]
    header.append("status")
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", newline="", encoding="utf-8") as f:
            w = csv.writer(f)
            w.writerow([f"# calib predict: {100 * prediction.confidence:.0f} % intervals of the model output"])
            w.writerow(header)
            for k in range(prediction.values.shape[0]):
                row = [f"{conditions[c][k]:.10g}" for c in CONDITION_FIELDS]
                for j in range(len(prediction.channels)):
                    row += [f"{prediction.values[k, j]:.10g}", f"{prediction.lower[k, j]:.10g}",
                            f"{prediction.upper[k, j]:.10g}"]
                row.append(Status(int(prediction.status[k])).name)
                w.writerow(row)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def run_predict(result_dir: str | Path, data: str | Path, out: str | Path, confidence: float = 0.95,
                printer=print) -> dict:
    """Predict the result's channels at the conditions of ``data``; returns the χ² figures (if measured).

    Returns
    -------
    dict
        ``n_points``, ``n_failed``, and when ``data`` holds measured channels of the result,
        ``chi2_per_dof`` overall and per channel.
    """
    result = load_result(result_dir)
    meas = read_measurements(data, None, allow_no_channels=True)
    pred = result.predict(meas.conditions, confidence=confidence)
    write_prediction_csv(out, meas.conditions.as_dict(), pred, {})
    figures = {"n_points": int(pred.values.shape[0]), "n_failed": int(np.count_nonzero(pred.status != 0))}
    printer(f"calib predict: {figures['n_points']} points, {figures['n_failed']} failed; wrote {out}")
    common = [c for c in meas.channels if c in pred.channels]
    if common:
        chi = {}
        total, n_total = 0.0, 0
        ok = pred.status == 0
        for c in common:
            j = pred.channels.index(c)
            sig_meas = meas.sigma[:, meas.channels.index(c)] if meas.sigma is not None else \
                np.full(len(ok), float(result.noise_sigma[result.channels.index(c)]))
            var = sig_meas ** 2 + pred.std[:, j] ** 2
            r2 = (meas.channel(c) - pred.values[:, j]) ** 2 / var
            chi[c] = float(np.mean(r2[ok]))
            total += float(np.sum(r2[ok]))
            n_total += int(ok.sum())
            printer(f"  {c}: chi2/dof {chi[c]:.3g} over {int(ok.sum())} points")
        figures["chi2_per_dof"] = total / max(n_total, 1)
        figures["chi2_per_dof_channels"] = chi
        printer(f"  overall: chi2/dof {figures['chi2_per_dof']:.3g} (sigma^2 = noise^2 + prediction variance)")
    elif meas.channels:
        printer(f"  note: measured channel(s) {', '.join(meas.channels)} are not channels of the result "
                f"({', '.join(result.channels)}); no comparison")
    return figures
