"""The calibration result: one object, in parts, that serializes to JSON + NPZ and loads back.

A :class:`CalibrationResult` holds the problem (parameters, channels, conditions) and five parts
(:mod:`calib.calibration.result_parts`): ``estimate``, ``identifiability``, ``uncertainty``, ``fit`` and
``provenance``. ``result.json`` holds the settings, the scalar figures of merit, the verdicts, the
history, the input SHA-256 hashes and the package versions, each under its part's name;
``result.npz`` holds every array as ``part.field`` (schema 3; a schema-2 file, every field under
its flat name, is read through :func:`calib.calibration.result_files.migrate_v2`). Both are written
atomically (temporary file, then rename); :func:`calib.calibration.result_files.load_result` reads them.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from calib.calibration.prediction import Prediction, predict_outputs
from calib.calibration.result_io import atomic_write, jsonable, write_npz_synced, write_text_synced
from calib.calibration.result_parts import ARRAY_FIELDS, PARTS, Estimate, Fit, Identifiability, Provenance, Uncertainty
from calib.errors import InputError
from calib.parametrizations.correction_field import NodeLayout, eigenshapes, node_layout
from calib.types import Parameter

__all__ = ["CalibrationResult", "DICT_ARRAYS", "SCHEMA_VERSION", "fold_sentence", "second_start_sentence"]

SCHEMA_VERSION = 3
DICT_ARRAYS = {"conditions": (None, "conditions__"), "polar_bands": ("uncertainty", "polar__"),
                "truncation": ("identifiability", "truncation__")}
"""Dicts of arrays stored in ``result.npz`` (the result's own, or its part's), each key under its prefix."""


def fold_sentence(fold_directions: list, conditions: dict | None = None, tsr=None) -> str:
    """One sentence on the retained θ that points with several roots of the BEM equations
    determine (``CalibrationResult.fold_directions``), from the numbers recorded there;
    ``conditions`` (``CalibrationResult.conditions``) and ``tsr`` name the operating point."""
    cond = dict(conditions or {})
    if tsr is not None:
        cond["tsr"] = tsr
    parts = []
    for d in fold_directions:
        where = f"point {d['point'] + 1}"
        labels = [(k, u) for k, u in (("wind_speed", "{:.3g} m/s"), ("tsr", "λ {:.3g}"), ("pitch", "pitch {:.3g}°"))
                  if k in cond and np.ndim(cond[k]) == 1 and d["point"] < len(cond[k])]
        if labels:
            where += " (" + ", ".join(u.format(float(cond[k][d["point"]])) for k, u in labels) + ")"
        sig = (f"; σ along it {d['sigma_before']:.2g} → {d['sigma_after']:.2g} scale units"
               if "sigma_after" in d else "")
        parts.append(f"θ{d['theta']} takes {100 * d['share']:.0f} % of its information from {where}, whose "
                     f"sensitivity is {d['sensitivity_ratio']:.3g}× the median point's{sig}")
    return ("Near a fold of the BEM residual (several roots at a section) the linearization can hold only on a "
            "narrow ridge: " + "; ".join(parts) + ". Such a θ is stated with its prior variance added, so its "
            "band is at least the prior's; the point can pull the rest of the fit too, which that does not "
            "correct: compare with a calibration without it.")


def second_start_sentence(truncation: dict) -> str:
    """One sentence on the automatic choice's second start (``CalibrationSettings.second_start``),
    from the numbers it recorded in ``truncation``."""
    t = truncation
    k1, k2 = int(t["first_retained"]), int(t["second_retained"])
    kept = "second" if int(t["second_kept"]) else "first"
    # results saved before the statuses were recorded have neither
    statuses = [str(t.get(f"{which}_status", "")) for which in ("first", "second")]
    differ = all(statuses) and (statuses[0] == "converged") != (statuses[1] == "converged")
    ends = [f", {s.replace('_', ' ')}" if differ else "" for s in statuses]
    rule = ("the one whose retained set settled" if differ else
            "the fewer θ" if k1 != k2 else "the first, at the same count")
    return (f"The first fit's χ² rejected the stated noise (p = {float(t['first_p_value']):.2g}), so the "
            f"choice was started again from the prior limit's count: from nominal it ended at {k1} θ (criterion "
            f"{float(t['first_cv']):.3g} ± {float(t['first_cv_se']):.2g}{ends[0]}), from the limit at {k2} θ "
            f"({float(t['second_cv']):.3g} ± {float(t['second_cv_se']):.2g}{ends[1]}); the {kept} was kept "
            f"({rule}, unless the other's criterion is lower by more than its standard error).")


@dataclass(eq=False)
class CalibrationResult:
    """Everything a calibration produced, in parts (:mod:`calib.calibration.result_parts`).

    Attributes
    ----------
    parameters : list of dict
        The parameters (:class:`calib.types.Parameter` as dicts).
    channels, channel_units : list of str
        The measured channels and their units.
    conditions : dict of str to ndarray, shape (m,)
        The operating conditions of the m points.
    estimate : Estimate
    identifiability : Identifiability
    uncertainty : Uncertainty
    fit : Fit
    provenance : Provenance
    name : str
        Name of the run (reports, files).
    json_path : Path or None
        The ``result.json`` it was loaded from (None for a result made in this process).

    Notes
    -----
    A field is read and set through its part, ``result.estimate.p_hat``; there are no flat
    names (``result.p_hat`` is an ``AttributeError`` that names the part).
    """

    parameters: list[dict]
    channels: list[str]
    channel_units: list[str]
    conditions: dict[str, np.ndarray]
    estimate: Estimate
    identifiability: Identifiability
    uncertainty: Uncertainty
    fit: Fit
    provenance: Provenance
    name: str = "calibration"
    json_path: Path | None = field(default=None, repr=False)

    def __getattr__(self, name: str):
        # only called when the normal lookup fails: say which part holds a field of the old flat names
        for part, cls in PARTS.items():
            if name in {f.name for f in fields(cls)}:
                raise AttributeError(f"{type(self).__name__} has no attribute {name!r}: it is "
                                     f"result.{part}.{name}")
        raise AttributeError(f"{type(self).__name__} has no attribute {name!r}")

    def replace(self, **changes) -> "CalibrationResult":
        """A copy with ``changes`` to the result's own fields or whole parts
        (``result.replace(fit=dataclasses.replace(result.fit, sigma=s))``). Every part is copied
        (shallow), so setting a field of the copy leaves this one alone."""
        own = dict(changes)
        for part in PARTS:
            own[part] = dataclasses.replace(own.get(part, getattr(self, part)))
        return dataclasses.replace(self, **own)

    # ------------------------------------------------------------------ derived
    def parameters_frame(self):
        """The parameters, estimates, σ, priors and verdicts as a DataFrame (:func:`calib.calibration.frames.parameters_frame`)."""
        from calib.calibration.frames import parameters_frame
        return parameters_frame(self)

    def points_frame(self):
        """Per point: measured, nominal, calibrated, residual, as a DataFrame (:func:`calib.calibration.frames.points_frame`)."""
        from calib.calibration.frames import points_frame
        return points_frame(self)

    @property
    def estimator(self) -> str:
        """``"map"`` or ``"truncated"`` (results written before the setting existed: truncated)."""
        return str(self.provenance.settings.get("estimator", "truncated"))

    @property
    def n_params(self) -> int:
        return int(self.estimate.p_hat.size)

    @property
    def n_retained(self) -> int:
        return int(np.count_nonzero(self.identifiability.retained))

    @property
    def n_points(self) -> int:
        return int(self.fit.measured.shape[0])

    @property
    def dof(self) -> int:
        """Degrees of freedom of χ² after: converged residuals minus retained parameters."""
        ok = self.fit.status_after == 0
        return int(ok.sum() * len(self.channels) - self.n_retained)

    @property
    def dof_before(self) -> int:
        """Degrees of freedom of χ² before: converged residuals of the nominal model (nothing fitted)."""
        return int((self.fit.status_before == 0).sum() * len(self.channels))

    @property
    def chi2_per_dof_before(self) -> float:
        return self.fit.chi2_before / max(self.dof_before, 1)

    @property
    def chi2_per_dof_after(self) -> float:
        return self.fit.chi2_after / max(self.dof, 1)

    def goodness_of_fit(self, n_worst: int = 5) -> dict:
        """χ² before (dof N) and after (dof N − n_retained), p-values, per channel, worst points.

        Returns
        -------
        dict
            ``chi2_before``, ``dof_before``, ``chi2_per_dof_before``, ``p_value_before``, the same
            ``_after``, ``per_channel`` {channel: {chi2_per_point_before, chi2_per_point_after,
            rms_before, rms_after}} and ``worst`` (list of {point, channel, whitened_residual}
            after calibration, largest |r| first).
        """
        from scipy import stats

        fit = self.fit
        out = {"chi2_before": fit.chi2_before, "dof_before": self.dof_before,
               "chi2_per_dof_before": self.chi2_per_dof_before,
               "p_value_before": float(stats.chi2.sf(fit.chi2_before, max(self.dof_before, 1))),
               "chi2_after": fit.chi2_after, "dof_after": self.dof, "chi2_per_dof_after": self.chi2_per_dof_after,
               "p_value_after": float(stats.chi2.sf(fit.chi2_after, max(self.dof, 1)))}
        per = {}
        rb, ra = self.rms("before"), self.rms("after")
        for i, c in enumerate(self.channels):
            row = {}
            for which, model, status in (("before", fit.model_before, fit.status_before),
                                         ("after", fit.model_after, fit.status_after)):
                ok = status == 0
                w = (fit.measured[ok, i] - model[ok, i]) / fit.sigma[ok, i]
                row[f"chi2_per_point_{which}"] = float(np.mean(w ** 2)) if w.size else float("nan")
            row["rms_before"], row["rms_after"] = rb[c], ra[c]
            per[c] = row
        out["per_channel"] = per
        ok = fit.status_after == 0
        w = np.where(ok[:, None], (fit.measured - np.where(ok[:, None], fit.model_after, 0.0)) / fit.sigma, 0.0)
        order = np.argsort(-np.abs(w), axis=None)[:n_worst]
        out["worst"] = [{"point": int(k // w.shape[1]), "channel": self.channels[int(k % w.shape[1])],
                         "whitened_residual": float(w.flat[k]),
                         "conditions": {n: float(v[k // w.shape[1]]) for n, v in self.conditions.items()}}
                        for k in order if ok[k // w.shape[1]]]
        return out

    def predict(self, conditions, model=None, confidence: float = 0.95, condition_sigma=None) -> Prediction:
        """Model outputs at new conditions with intervals from the estimate's covariance
        (:func:`calib.calibration.prediction.predict_outputs`; ``model`` default: rebuilt from ``model_spec``;
        ``condition_sigma`` (n_points, 4), or 3 without the air density's: the conditions' 1-σ carried into the intervals)."""
        return predict_outputs(self, conditions, self.rebuild_model() if model is None else model, confidence,
                               condition_sigma)

    def rebuild_model(self):
        """The forward model rebuilt from ``model_spec``.

        A native-BEM result rebuilds its rotor from the rotor data it recorded, wherever its
        folder now is; one written by an older version without them rebuilds it from the
        recorded rotor files (at their recorded paths, else in the result's folder), refused
        when one is missing or changed since the run. An FMU result needs its FMU and mapping
        files unchanged (:func:`calib.models.registry.check_fmu_files`).

        Raises
        ------
        InputError
            No model spec recorded, or recorded files missing or changed (the file named).
        """
        json_path = self.json_path
        folder = None if json_path is None else json_path.parent
        where = str(json_path) if json_path is not None else self.name
        if not self.provenance.model_spec:
            raise InputError("this result recorded no model spec to rebuild its model; pass model=", where,
                             field="model_spec")
        from calib.models.registry import build_model

        return build_model(self.provenance.model_spec, base_dir=folder, source=f"{where}: provenance.model_spec")

    @property
    def parameter_objects(self) -> tuple[Parameter, ...]:
        keys = {f.name for f in fields(Parameter)}
        return tuple(Parameter(**{k: v for k, v in d.items() if k in keys}) for d in self.parameters)

    @property
    def layout(self) -> NodeLayout:
        return node_layout(self.parameter_objects)

    def verdict_counts(self) -> dict[str, int]:
        out = {"identified": 0, "poorly observable": 0, "at bound": 0, "confounded": 0}
        for v in self.identifiability.verdicts:
            out[v["verdict"]] = out.get(v["verdict"], 0) + 1
        return out

    def rms(self, which: str = "after") -> dict[str, float]:
        """Per-channel RMS of the residual (converged points) [channel units]."""
        model = self.fit.model_after if which == "after" else self.fit.model_before
        status = self.fit.status_after if which == "after" else self.fit.status_before
        ok = status == 0
        return {c: float(np.sqrt(np.mean((self.fit.measured[ok, i] - model[ok, i]) ** 2)))
                for i, c in enumerate(self.channels)}

    def tip_speed_ratio(self) -> np.ndarray | None:
        """λ = ΩR/V of each point [-] (None when the rotor radius is unknown)."""
        if not self.provenance.rotor_radius:
            return None
        cond = self.conditions
        return cond["rotor_speed"] * np.pi / 30.0 * self.provenance.rotor_radius / cond["wind_speed"]

    def eigenshapes(self, alpha_deg, eta, modes=None):
        """Lift and drag eigenshapes (n_modes, n_eta, n_alpha) of the given modes (default: retained)."""
        if modes is None:
            modes = np.flatnonzero(self.identifiability.retained)
        return eigenshapes(self.identifiability.V, self.layout, alpha_deg, eta, modes)

    def noise_words(self) -> str:
        """Which noise the χ² figures are taken against, with its σ per channel: "the σ estimated with
        the fit (ml): power 1.2e+04 W, thrust 3.1e+03 N" (two χ² of one run, the unit check's and the
        calibration's, are read apart by it)."""
        noise = str(self.provenance.settings.get("noise", "known"))
        how = {"known": "the stated σ", "repeats": "the σ of the repeated records",
               "ml": "the σ estimated with the fit",
               "relative": "the stated σ relative to each point's value",
               "relative_ml": "the stated relative σ times a factor estimated with the fit"}.get(noise, noise)
        if noise in ("relative", "relative_ml"):
            return f"{how} ({noise})"
        sig = ", ".join(f"{c} {float(s):.3g} {u}" for c, u, s in zip(self.channels, self.channel_units,
                                                                      self.fit.noise_sigma))
        return f"{how} ({noise}): {sig}"

    def summary(self) -> str:
        """A few plain lines with the key numbers."""
        counts = self.verdict_counts()
        ident, unc = self.identifiability, self.uncertainty
        how = (f"chosen by {ident.truncation.get('criterion', 'K-fold')} cross-validation over operating "
               "points" if ident.truncation else "set")
        if self.estimator == "map":
            kept = (f"  parameters {self.n_params}, MAP estimate under the stated prior; the data determine "
                    f"{self.n_retained} directions better than the prior (s > 1)")
        else:
            kept = (f"  parameters {self.n_params}, retained {self.n_retained} (sigma_bar = {ident.sigma_bar:.3g}, "
                    f"{how})")
        lines = [f"{self.name}: {self.estimate.status} ({self.estimate.message})", kept,
                 f"  chi2/dof before {self.chi2_per_dof_before:.3g} (dof {self.dof_before}), after "
                 f"{self.chi2_per_dof_after:.3g} (dof {self.dof})",
                 "  verdicts: " + ", ".join(f"{k} {v}" for k, v in counts.items()),
                 "  failed model points: " + ", ".join(f"{k} {v}" for k, v in self.fit.failures.items())]
        if "second_retained" in ident.truncation:
            lines.append("  " + second_start_sentence(ident.truncation))
        if unc.prior_check.get("failed"):
            lines.append(f"  prior check: failed ({unc.prior_check['failed']})")
        elif unc.prior_check:
            pc = unc.prior_check
            lines.append(f"  prior check: field amplitude {pc['amplitude']:.2g} x stated "
                         f"({100 * pc['confidence']:.0f} % interval {pc['lower']:.2g}-{pc['upper']:.2g}), "
                         f"{pc['verdict']}")
        if ident.fold_directions:
            lines.append("  " + fold_sentence(ident.fold_directions, self.conditions, self.tip_speed_ratio()))
        rb, ra = self.rms("before"), self.rms("after")
        for c in self.channels:
            lines.append(f"  rms {c}: {rb[c]:.4g} -> {ra[c]:.4g}")
        return "\n".join(lines)

    # ------------------------------------------------------------------ i/o
    def to_json_dict(self) -> dict:
        """``result.json``: the problem, each part's fields that are not arrays (under the part's
        name) and a summary."""
        doc = {"schema_version": SCHEMA_VERSION, "parameters": self.parameters, "channels": self.channels,
               "channel_units": self.channel_units, "name": self.name}
        for part in PARTS:
            doc[part] = {k: v for k, v in vars(getattr(self, part)).items()
                         if (part, k) not in ARRAY_FIELDS and k not in DICT_ARRAYS}
        ident = self.identifiability
        truncation = {"criterion": f"{ident.truncation.get('criterion')} cross-validation",
                      "chosen": ident.truncation.get("chosen"), "sigma_bar": ident.sigma_bar} if ident.truncation \
            else {"criterion": "threshold", "sigma_bar": ident.sigma_bar}
        doc["summary"] = {"n_params": self.n_params, "n_retained": self.n_retained, "dof": self.dof,
                          "goodness_of_fit": self.goodness_of_fit(), "truncation": truncation,
                          "verdict_counts": self.verdict_counts()}
        return jsonable(doc)

    def save(self, out_dir: str | Path, stem: str = "result") -> tuple[Path, Path]:
        """Write ``<stem>.json`` and ``<stem>.npz`` into ``out_dir`` (atomically)."""
        out_dir = Path(out_dir)
        jpath, npath = out_dir / f"{stem}.json", out_dir / f"{stem}.npz"
        atomic_write(jpath, write_text_synced(json.dumps(self.to_json_dict(), indent=1, allow_nan=True)))
        arrays = {f"{part}.{k}": np.asarray(getattr(getattr(self, part), k)) for part, k in ARRAY_FIELDS}
        for name, (owner, prefix) in DICT_ARRAYS.items():
            values = self.conditions if owner is None else getattr(getattr(self, owner), name)
            arrays.update({f"{prefix}{k}": np.asarray(v) for k, v in values.items()})
        atomic_write(npath, write_npz_synced(arrays))
        return jpath, npath
