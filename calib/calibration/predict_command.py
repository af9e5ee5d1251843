"""``calib predict RESULT_DIR --data FILE.csv --out PRED.csv``: a calibrated model at new conditions.

The result rebuilds its model from the spec it recorded, evaluates it at the conditions of
FILE.csv and writes, next to the conditions, for each channel of the result
``<channel>``, ``<channel>_lower`` and ``<channel>_upper`` (the 95 % interval of the model
output, :meth:`calib.calibration.result.CalibrationResult.predict`) in SI units, a ``status`` column,
and ``envelope`` (``inside`` / ``outside``) with ``outside_because`` (what lies outside the
calibration's operating ranges or the angles of attack it reached; :mod:`calib.checks.envelope`). When FILE.csv also holds measured channels, χ²/dof of measured against predicted is
printed per channel and overall, with σ² = σ_meas² + σ_pred² (σ_meas from the ``_sigma``
columns, else the noise the calibration used).
"""

from __future__ import annotations

import csv
import dataclasses
import os
import tempfile
from pathlib import Path

import numpy as np

from calib.calibration.prediction import Prediction
from calib.calibration.result_files import load_result
from calib.measurements import read_measurements
from calib.types import CONDITION_FIELDS, Status


def write_prediction_csv(path: str | Path, conditions: dict, prediction: Prediction, units: dict) -> Path:
    """Write conditions and predictions with their intervals (atomically)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cond_units = {"wind_speed": "m/s", "rotor_speed": "rpm", "pitch": "deg", "air_density": "kg/m^3", "yaw": "deg"}
    header = [f"{c} [{cond_units[c]}]" for c in CONDITION_FIELDS]
    for c, u in zip(prediction.channels, prediction.units):
        header += [f"{c} [{u}]", f"{c}_lower [{u}]", f"{c}_upper [{u}]"]
    header += ["status", "envelope", "outside_because"]
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
                why = prediction.envelope[k] if prediction.envelope else ""
                row += ["outside" if why else "inside", why]
                w.writerow(row)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def _span(values, fmt: str) -> str:
    """``fmt`` of the one value, or of the range of several [same unit]."""
    a = np.asarray(values, float).ravel()
    if a.size == 0:
        return "none"
    lo, hi = float(np.min(a)), float(np.max(a))
    return fmt.format(lo) if lo == hi else f"{fmt.format(lo)}-{fmt.format(hi)}"


def setup_lines(spec: dict | None, recorded: dict | None, conditions: dict, data: str,
                rotor_name: str | None = None) -> list[str]:
    """The recorded set-up a prediction runs with, in two lines.

    Parameters
    ----------
    spec : dict or None
        The result's ``model_spec``.
    recorded : dict or None
        The calibration's conditions (``CalibrationResult.conditions``): the air density and
        yaw it was calibrated at.
    conditions : dict
        The prediction's conditions (``OperatingConditions.as_dict()``).
    data : str
        The prediction's conditions file (named).
    rotor_name : str, optional
        The rebuilt model's rotor name (for a result that recorded no rotor data).

    Returns
    -------
    list of str
        Model line: rotor name and source (and whether it is the result's recorded rotor
        data or rebuilt from files), tilt [deg] (and whether the BEM applies it), precone
        [deg], shear exponent [-], azimuth sectors, kinematic viscosity [m^2/s], nuisance
        parameters and effects; or the FMU and mapping files. Conditions line: air density
        [kg/m^3] and yaw [deg] of the prediction, with the calibration's.
    """
    spec = spec or {}
    lines = []
    if spec.get("kind") == "bem":
        data_ = spec.get("rotor_data") or {}
        table = spec.get("rotor") or {}
        name = data_.get("name") or table.get("name") or rotor_name or "?"
        origin = ("the result's recorded rotor data" if data_ else
                  "the embedded rotor of this calib version" if set(table) == {"name"} else
                  "the rotor files (the result records no rotor data)")
        where = data_.get("source") or ", ".join(f"{k} {v}" for k, v in table.items() if k in ("openfast", "aerodyn",
                                                                                                 "aerodyn_blade",
                                                                                                 "windio"))
        st = spec.get("settings") or {}
        sectors = st.get("n_sectors")
        model = [f"rotor {name} ({where}; from {origin})"]
        if "tilt_deg" in spec:
            model.append(f"tilt {spec['tilt_deg']:g} deg" + ("" if st.get("use_tilt", True) else " (not applied, "
                                                                                                 "use_tilt = false)"))
        if "precone_deg" in spec:
            model.append(f"precone {spec['precone_deg']:g} deg")
        if "shear_exponent" in st:
            model.append(f"shear exponent {st['shear_exponent']:g}")
        model.append(f"sectors {'automatic' if sectors is None else sectors}")
        if "kinematic_viscosity" in st:
            model.append(f"kinematic viscosity {st['kinematic_viscosity']:.4g} m^2/s")
        model.append(f"nuisance {', '.join(spec.get('nuisance') or []) or 'none'}")
        effects = [e.get("name", "?") if isinstance(e, dict) else str(e) for e in spec.get("effects") or []]
        if effects:
            model.append(f"effects {', '.join(effects)}")
        lines.append("calib predict: set-up recorded by the result: " + ", ".join(model))
    elif spec.get("kind") == "fmu":
        lines.append(f"calib predict: set-up recorded by the result: FMU {spec.get('fmu')}, mapping "
                     f"{spec.get('mapping')}")
    cond = [f"air density {_span(conditions['air_density'], '{:.4g}')} kg/m^3",
            f"yaw {_span(conditions['yaw'], '{:g}')} deg"]
    line = f"  conditions of {data}: " + ", ".join(cond)
    if recorded and "air_density" in recorded and "yaw" in recorded:
        line += (f" (calibrated at air density {_span(recorded['air_density'], '{:.4g}')} kg/m^3, yaw "
                 f"{_span(recorded['yaw'], '{:g}')} deg)")
    lines.append(line)
    return lines


def calibration_fluid(meas, recorded: dict | None, printer=print):
    """The prediction's table with the calibration's air density where it has no ``air_density``
    column (a water rotor calibrated at 1000 kg/m^3 is not predicted in air), said in a line.

    Parameters
    ----------
    meas : Measurements
        The prediction's conditions as read.
    recorded : dict or None
        The calibration's conditions (``CalibrationResult.conditions``).
    printer : callable(str)
    """
    units = meas.metadata.get("units") or {}
    density = np.unique(np.asarray((recorded or {}).get("air_density", []), float))
    if "air_density" in units or density.size != 1:
        return meas
    cond = dataclasses.replace(meas.conditions, air_density=np.full(meas.n_points, float(density[0])))
    printer(f"calib predict: no air_density column in the data: the calibration's {density[0]:.4g} kg/m^3 used")
    return dataclasses.replace(meas, conditions=cond)


def data_condition_sigma(meas) -> np.ndarray | None:
    """The data's ``wind_speed_sigma``, ``rotor_speed_sigma``, ``pitch_sigma``, ``air_density_sigma`` columns
    as an (n_points, 4) array [m/s, rpm, deg, kg/m^3] (0 for a condition without a column), None without any."""
    if not meas.condition_sigma:
        return None
    from calib.calibration.settings import UNCERTAIN_CONDITIONS
    return np.column_stack([np.broadcast_to(np.asarray(meas.condition_sigma.get(c, 0.0), float), meas.n_points)
                            for c in UNCERTAIN_CONDITIONS])


def print_condition_share(pred: Prediction, printer) -> None:
    """Print the conditions' share of the interval variance (median over the points), if any."""
    if pred.condition_std is None:
        return
    with np.errstate(all="ignore"):
        share = np.nanmedian(pred.condition_std ** 2 / pred.std ** 2, axis=0)
    printer("  intervals carry the conditions' uncertainty (the data's _sigma columns); its share of the interval "
            "variance (median over the points): " + ", ".join(
                f"{c} {100 * v:.0f} %" for c, v in zip(pred.channels, share) if np.isfinite(v)))


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
    meas = calibration_fluid(read_measurements(data, None, allow_no_channels=True), result.conditions, printer)
    model = result.rebuild_model()
    rotor_name = ((result.provenance.model_spec or {}).get("rotor_data") or {}).get("name")   # the native BEM's, if any
    for line in setup_lines(result.provenance.model_spec, result.conditions, meas.conditions.as_dict(), str(data),
                            rotor_name):
        printer(line)
    pred = result.predict(meas.conditions, model=model, confidence=confidence, condition_sigma=data_condition_sigma(meas))
    write_prediction_csv(out, meas.conditions.as_dict(), pred, {})
    figures = {"n_points": int(pred.values.shape[0]), "n_failed": int(np.count_nonzero(pred.status != 0))}
    printer(f"calib predict: {figures['n_points']} points, {figures['n_failed']} failed; wrote {out}")
    outside = pred.outside
    figures["n_outside"] = int(outside.sum())
    if outside.any():
        first = int(np.flatnonzero(outside)[0])
        printer(f"  {int(outside.sum())} of {len(outside)} points lie outside the calibration envelope (extrapolation; "
                f"the CSV's envelope and outside_because columns say which and why), e.g. point {first + 1}: "
                f"{pred.envelope[first]}")
    else:
        printer("  every point lies inside the calibration envelope (operating ranges and the angles of attack "
                "the calibration reached at each station)")
    if pred.representation:
        printer(f"  intervals: {pred.representation}")
    if pred.discrepancy:
        printer(f"  intervals: {pred.discrepancy}")
    if pred.discrepancy_std is not None and np.nanmax(np.nan_to_num(pred.discrepancy_std), initial=0.0) > 0:
        with np.errstate(all="ignore"):
            share = np.nanmedian(pred.discrepancy_std ** 2 / pred.std ** 2, axis=0)
        printer("  model discrepancy's share of the interval variance (median over the points): " + ", ".join(
            f"{c} {100 * v:.0f} %" for c, v in zip(pred.channels, share) if np.isfinite(v)))
    if pred.field_std is not None and np.nanmax(np.nan_to_num(pred.field_std), initial=0.0) > 0:
        with np.errstate(all="ignore"):
            share = np.nanmedian(pred.field_std ** 2 / pred.std ** 2, axis=0)
        printer("  the field between and beyond the nodes' share of the interval variance (median over the points): "
                + ", ".join(f"{c} {100 * v:.0f} %" for c, v in zip(pred.channels, share) if np.isfinite(v)))
    print_condition_share(pred, printer)
    common = [c for c in meas.channels if c in pred.channels]
    if common:
        chi = {}
        total, n_total = 0.0, 0
        ok = pred.status == 0
        for c in common:
            j = pred.channels.index(c)
            sig_meas = meas.sigma[:, meas.channels.index(c)] if meas.sigma is not None else \
                np.full(len(ok), float(result.fit.noise_sigma[result.channels.index(c)]))
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
