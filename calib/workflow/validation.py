"""Validation of a workflow's stages on held-back measurements, and the workflow report's section on it.

A ``[validation]`` table makes each stage repeat its calibration with the points of one operating
condition left out (e.g. one wind speed at a time), or with one band of it (calibrate at low wind,
predict at high wind, and the reverse), and predict them with 95 % prediction intervals: the model
output's interval (:meth:`calib.calibration.result.CalibrationResult.predict`, frozen directions included)
combined with the noise σ of a new measurement. The stages run after the diagnosis of
``[diagnosis]`` (:mod:`calib.diagnosis.in_workflow`), whose named effects the figures here show.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import stats

from calib.calibration.calibrator import CalibrationSettings, Calibrator
from calib.config import NUM, Key, in_open_unit_interval, names_list, settings_from_table
from calib.diagnosis.in_workflow import diagnosis_sentence
from calib.errors import CalibError, InputError
from calib.measurements import Measurements

#: How held-back points are chosen: one value of the condition at a time, or two bands of it.
SPLITS = ("one", "band")
#: Operating conditions a validation may leave out one value of at a time ("point": each point).
LEAVE_OUT = ("wind_speed", "rotor_speed", "pitch", "point")
#: [validation] keys of a workflow (:func:`calib.config.check_table`).
VALIDATION_SCHEMA = {"leave_out": Key(str, choices=LEAVE_OUT), "split": Key(str, choices=SPLITS),
                     "band_at": Key(NUM), "channels": Key(list, check=names_list),
                     "confidence": Key(NUM, check=in_open_unit_interval)}


@dataclass(frozen=True)
class ValidationSettings:
    """Settings of :func:`leave_one_out` (a workflow's ``[validation]`` table).

    Parameters
    ----------
    leave_out : {"wind_speed", "rotor_speed", "pitch", "point"}
        The condition whose values are held back.
    split : {"one", "band"}
        ``"one"`` (default): each value left out in turn (leave-one-out). ``"band"``: calibrate
        on the values at or below ``band_at`` and predict those above, then the reverse: the
        extrapolation an engineer needs (calibrated at low wind, used at high wind).
    band_at : float, optional
        Where the bands part [unit of ``leave_out``]; default: the median of the distinct values
        (the lower band takes it).
    channels : tuple of str, optional
        Channels scored (default: every channel of the stage).
    confidence : float
        Level of the prediction intervals.
    """

    leave_out: str = "wind_speed"
    channels: tuple | None = None
    confidence: float = 0.95
    split: str = "one"
    band_at: float | None = None

    @classmethod
    def from_table(cls, table: dict, source: str) -> "ValidationSettings":
        """The settings of a ``[validation]`` table (:func:`calib.config.settings_from_table`), checked."""
        settings = settings_from_table(cls, table, "validation", source, VALIDATION_SCHEMA)
        if settings.split == "band" and settings.leave_out == "point":
            raise InputError("a band split needs a condition (wind_speed, rotor_speed or pitch), not 'point'", source,
                             field="validation.leave_out")
        if settings.band_at is not None and settings.split != "band":
            raise InputError(f"must be given with split = \"band\" only; got {table['band_at']!r}", source,
                             field="validation.band_at")
        return settings if settings.channels else dataclasses.replace(settings, channels=None)

    def folds(self, groups: np.ndarray, source: str) -> list[tuple[str, np.ndarray]]:
        """(label, held-back mask) of every fold over the condition values ``groups``."""
        values = np.unique(groups)
        if self.split == "one":
            if values.size < 3:
                raise InputError(f"leave-one-out over {self.leave_out} needs at least 3 distinct values, found "
                                 f"{values.size}", source, field="validation.leave_out")
            return [(f"{self.leave_out} = {g:g} held back", groups == g) for g in values]
        at = float(values[(values.size - 1) // 2]) if self.band_at is None else self.band_at
        low, high = groups <= at, groups > at
        if not low.any() or not high.any():
            raise InputError(f"a band split at {at:g} leaves one band empty ({self.leave_out} spans "
                             f"{values.min():g} to {values.max():g})", source, field="validation.band_at")
        name = self.leave_out.replace("_", " ")
        return [(f"calibrated at {name} <= {at:g}, predicting above", high),
                (f"calibrated at {name} > {at:g}, predicting at or below", low)]


@dataclass
class FoldRow:
    """One held-out point of one channel."""

    group: float
    channel: str
    measured: float
    nominal: float
    predicted: float
    lower: float
    upper: float
    model_std: float
    noise_std: float
    n_retained: int
    status: str
    fold: str = ""
    outside: str = ""      # why the point lies outside the fold's calibration envelope ("" inside)
    field_std: float = float("nan")         # the part of model_std from the field between/beyond the nodes
    field_amplitude: float = float("nan")   # its amplitude in the stated prior's units (1 inside the envelope)
    prior_amplitude: float = float("nan")   # the fold's prior check τ̂ (NaN: not run)

    @property
    def inside(self) -> bool:
        return bool(self.lower <= self.measured <= self.upper)


@dataclass
class Validation:
    """What :func:`leave_one_out` found (``to_dict`` is ``validation.json``)."""

    leave_out: str
    confidence: float
    rows: list = field(default_factory=list)
    units: dict = field(default_factory=dict)
    split: str = "one"

    def channels(self) -> list[str]:
        return list(dict.fromkeys(r.channel for r in self.rows))

    def summary(self, channel: str) -> dict:
        """Mean absolute error and χ² per point of the nominal and the calibrated model at the
        held-back points (calibrated: σ² = noise² + prediction variance; nominal: noise²), how
        many held-back measurements fall inside the prediction intervals, and how many held-back
        points lay outside their fold's calibration envelope."""
        rows = [r for r in self.rows if r.channel == channel and np.isfinite(r.predicted)]
        err_nom = [abs(r.measured - r.nominal) for r in rows if np.isfinite(r.nominal)]
        chi_nom = [((r.measured - r.nominal) / r.noise_std) ** 2 for r in rows if np.isfinite(r.nominal)]
        chi_cal = [(r.measured - r.predicted) ** 2 / (r.noise_std ** 2 + r.model_std ** 2) for r in rows]
        return {"channel": channel, "unit": self.units.get(channel, ""), "folds": len(rows),
                "mean_abs_error_nominal": float(np.mean(err_nom)) if err_nom else float("nan"),
                "mean_abs_error_calibrated": float(np.mean([abs(r.measured - r.predicted) for r in rows]))
                if rows else float("nan"),
                "chi2_per_point_nominal": float(np.mean(chi_nom)) if chi_nom else float("nan"),
                "chi2_per_point_calibrated": float(np.mean(chi_cal)) if chi_cal else float("nan"),
                "inside": int(sum(r.inside for r in rows)),
                "outside_envelope": int(sum(bool(r.outside) for r in rows)),
                "failed": int(sum(1 for r in self.rows if r.channel == channel and not np.isfinite(r.predicted)))}

    def sentence(self, channel: str) -> str:
        s = self.summary(channel)
        better = s["mean_abs_error_calibrated"] < s["mean_abs_error_nominal"]
        how = (f"one {self.leave_out.replace('_', ' ')} left out at a time ({s['folds']} folds" if self.split == "one"
               else f"calibrated on one band of {self.leave_out.replace('_', ' ')} and predicting the other "
                    f"({s['folds']} held-back points")
        return (f"{channel}, {how}" + (f", {s['failed']} failed" if s["failed"] else "") + "): mean |error| at the "
                f"held-back points {s['mean_abs_error_calibrated']:.4g} {s['unit']} calibrated vs "
                f"{s['mean_abs_error_nominal']:.4g} {s['unit']} nominal ({'better' if better else 'NOT better'}); χ² "
                f"per point {s['chi2_per_point_calibrated']:.3g} calibrated vs {s['chi2_per_point_nominal']:.3g} "
                f"nominal; {s['inside']} of {s['folds']} held-back measurements inside the "
                f"{100 * self.confidence:g} % prediction intervals; {s['outside_envelope']} outside their fold's "
                f"calibration envelope")

    def to_dict(self) -> dict:
        return {"leave_out": self.leave_out, "split": self.split, "confidence": self.confidence,
                "summary": [self.summary(c) for c in self.channels()],
                "rows": [{**dataclasses.asdict(r), "inside": r.inside} for r in self.rows]}

    def write_csv(self, path) -> None:
        from calib.report.atomic import atomic_path

        head = [self.leave_out, "channel", "measured", "nominal", "predicted", "lower", "upper", "model_std",
                "noise_std", "inside", "n_retained", "status", "fold", "outside_because"]
        with atomic_path(path) as tmp:
            with open(tmp, "w") as f:
                f.write(",".join(head) + "\n")
                for r in self.rows:
                    f.write(",".join([f"{r.group:.6g}", r.channel] + [f"{v:.8g}" for v in (
                        r.measured, r.nominal, r.predicted, r.lower, r.upper, r.model_std, r.noise_std)]
                        + [str(r.inside).lower(), str(r.n_retained), r.status, _csv_text(r.fold),
                           _csv_text(r.outside)]) + "\n")


def _csv_text(text: str) -> str:
    """A CSV field: quoted when it holds a comma or a quote."""
    return '"' + text.replace('"', '""') + '"' if ("," in text or '"' in text) else text


def _groups(measurements: Measurements, leave_out: str) -> np.ndarray:
    if leave_out == "point":
        return np.arange(measurements.n_points, dtype=float)
    return np.round(np.asarray(getattr(measurements.conditions, leave_out), float), 6)


def leave_one_out(make_model: Callable, measurements: Measurements, settings: CalibrationSettings,
                  validation: ValidationSettings = ValidationSettings(),
                  progress: Callable[[str], None] | None = None) -> Validation:
    """Calibrate with points held back (one value of a condition at a time, or a band of it) and
    predict the points held back.

    Parameters
    ----------
    make_model : callable() -> ForwardModel
        A fresh model of the stage (same channels as ``measurements``).
    measurements : Measurements
    settings : CalibrationSettings
        As for the full calibration (noise model, truncation).
    validation : ValidationSettings
    progress : callable(str), optional

    Returns
    -------
    Validation
        Per held-out point and channel: the measurement, the nominal model, the prediction
        and its interval. The interval combines the model output's variance with the noise
        variance of a new measurement: the ``_sigma`` of the held-out row when the table has
        one, else the σ the fold's calibration used for that channel (constant per channel
        for ``noise = "ml"``, ``"relative"`` and ``"relative_ml"``).
    """
    say = progress or (lambda s: None)
    groups = _groups(measurements, validation.leave_out)
    folds = validation.folds(groups, measurements.source)
    channels = list(validation.channels or measurements.channels)
    missing = [c for c in channels if c not in measurements.channels]
    if missing:
        raise InputError(f"channel(s) {', '.join(missing)} not in this stage ({', '.join(measurements.channels)})",
                         measurements.source, field="validation.channels")
    z = float(stats.norm.ppf(0.5 * (1 + validation.confidence)))
    model = make_model()
    names = [c.name for c in model.channels]
    units = {c.name: c.unit for c in model.channels}
    p0 = np.array([q.nominal for q in model.parameters])
    nominal = model.evaluate(p0, measurements.conditions)
    y_nom = nominal.values[:, [names.index(c) for c in measurements.channels]]
    out = Validation(validation.leave_out, validation.confidence, units={c: units.get(c, "") for c in channels},
                     split=validation.split)
    for i, (label, test) in enumerate(folds):
        train = measurements.select_points(~test)
        try:
            # a fold's result serves its prediction only: no advice; the prior check only where the bands
            # carry the field beyond the nodes at the amplitude it bounds (the MAP's, prediction.field_amplitude)
            res = Calibrator(make_model(), train, dataclasses.replace(
                settings, prior_check=settings.prior_check and settings.estimator == "map", tightening=False),
                name=f"fold {i + 1}").run()
            pred = res.predict(measurements.conditions.subset(test), model=make_model(),
                               confidence=validation.confidence)
            status = res.estimate.status
        except CalibError as exc:   # a failed fold is counted and shown, the others go on
            say(f"fold {i + 1}/{len(folds)} ({label}) failed: {exc}")
            res, pred, status = None, None, f"failed: {type(exc).__name__}"
        for c in channels:
            j = list(measurements.channels).index(c)
            for kk, k in enumerate(np.flatnonzero(test)):     # kk: row of the prediction, k: of the table
                g = float(groups[k])
                if pred is None or not np.isfinite(pred.values[kk, j]):
                    out.rows.append(FoldRow(g, c, float(measurements.values[k, j]), float(y_nom[k, j]),
                                            np.nan, np.nan, np.nan, np.nan, np.nan,
                                            -1 if res is None else res.n_retained, status, label))
                    continue
                noise = float(measurements.sigma[k, j]) if measurements.sigma is not None else float(
                    np.median(res.fit.sigma[:, j]))
                sd = float(pred.std[kk, j])
                half = z * float(np.hypot(sd, noise))
                yk = float(pred.values[kk, j])
                why = pred.envelope[kk] if pred.envelope else ""
                fsd = float(pred.field_std[kk, j]) if pred.field_std is not None else float("nan")
                out.rows.append(FoldRow(g, c, float(measurements.values[k, j]), float(y_nom[k, j]), yk,
                                        yk - half, yk + half, sd, noise, res.n_retained, status, label, why,
                                        fsd, pred.field_amplitude if pred.outside[kk] else 1.0,
                                        float(res.uncertainty.prior_check.get("amplitude", np.nan))))
        if res is not None:
            say(f"fold {i + 1}/{len(folds)} ({label}): {res.n_retained} θ retained, {res.estimate.status}")
    return out


# ----------------------------------------------------------------------------- workflow steps
def write_validation(validation: Validation, stage_dir) -> None:
    """``validation.csv`` and ``validation.json`` in a stage folder (atomically)."""
    import json
    from pathlib import Path

    from calib.report.atomic import atomic_path

    stage_dir = Path(stage_dir)
    validation.write_csv(stage_dir / "validation.csv")
    with atomic_path(stage_dir / "validation.json") as tmp:
        Path(tmp).write_text(json.dumps(validation.to_dict(), indent=1, default=float))


def campaign_figure(setup, measurements: Measurements, grid, outcomes, diag, validations: dict, effects,
                    channels, title: str, executor=None):
    """:func:`calib.report.validation_figures.plot_campaign` for ``channels`` of a workflow's stages."""
    from calib.report.validation_figures import plot_campaign, predict_channels

    meas = measurements.select_channels(channels)
    model = setup.model(grid, channels, executor, effects)
    nominal_model = setup.model(None, channels, executor)
    nominal = nominal_model.evaluate(np.array([q.nominal for q in nominal_model.parameters], float),
                                     meas.conditions).values
    with_effects = None
    if diag is not None and diag.effects and all(c in diag.channels for c in channels):
        with_effects = diag.model_with_effects[:, [diag.channels.index(c) for c in channels]]
    stages = {}
    for o in outcomes:
        names, vals, half = predict_channels(o.result, model, meas.conditions)
        stages[o.name] = (vals[:, [names.index(c) for c in channels]], half[:, [names.index(c) for c in channels]])
    units = {c.name: c.unit for c in model.channels}
    return plot_campaign(channels, meas.values, np.asarray(meas.conditions.wind_speed, float), nominal,
                         with_effects, " + ".join(diag.effects) if diag is not None and diag.effects else "",
                         stages, validations, title=title, units=units)


def section_html(diag, validations: dict) -> str:
    """HTML of the diagnosis's verdict and the leave-one-out tables."""
    import html

    parts = []
    if diag is not None:
        parts.append("<h2>Diagnosis</h2><p>" + html.escape(diagnosis_sentence(diag))
                     + ' <a href="diagnosis/report.html">Full diagnosis report</a>.</p>')
    for name, val in validations.items():
        kind = "Leave-one-out validation" if val.split == "one" else "Validation by extrapolation (band split)"
        parts.append(f"<h2>{kind}: {html.escape(name)}</h2>")
        for c in val.channels():
            parts.append("<p>" + html.escape(val.sentence(c)) + "</p>")
        head = [val.leave_out.replace("_", " "), "channel", "measured", "nominal", "predicted", "95 % PI",
                "inside", "θ retained", "envelope"]
        rows = "".join(
            "<tr>" + "".join(f"<td>{html.escape(str(v))}</td>" for v in (
                f"{r.group:g}", r.channel, f"{r.measured:.4g}", f"{r.nominal:.4g}", f"{r.predicted:.4g}",
                f"{r.lower:.4g} … {r.upper:.4g}", "yes" if r.inside else "NO", r.n_retained,
                f"outside: {r.outside}" if r.outside else "inside")) + "</tr>"
            for r in val.rows)
        parts.append('<div style="overflow-x:auto"><table><tr>' + "".join(f"<th>{h}</th>" for h in head)
                     + "</tr>" + rows + "</table></div>")
    return "\n".join(parts)


#: s_i at or above which a direction counts as informed by the data (σ_θ <= 2 prior units).
INFORMED_LEVEL = 0.5


def informed_eigenshapes(result, block: str = "lift", level: float = INFORMED_LEVEL, max_modes: int = 12):
    """Lift (or drag) eigenshapes of every direction with s_i >= ``level``, retained or not:
    what the data could tell apart, which the retained set alone (chosen for prediction) may
    not show. None when the result has no correction field."""
    from calib.report.eigenshape_figures import plot_eigenshapes

    modes = np.flatnonzero(np.asarray(result.identifiability.singular_values) >= level)[:max_modes]
    return plot_eigenshapes(result, block, modes=modes,
                            which=f"directions the data inform (s_i ≥ {level:g}, retained or not)")
