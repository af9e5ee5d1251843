"""The calibration result: one object that serializes to JSON + NPZ and loads back.

``result.json`` holds the settings, the scalar figures of merit, the verdicts, the
history, the input SHA-256 hashes and the package versions; ``result.npz`` holds every
array. Both are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import enum
import json
import os
import platform
import tempfile
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from calib.envelope import envelope_of
from calib.errors import InputError
from calib.identifiability import NodeLayout, eigenshapes, node_layout
from calib.types import Parameter

SCHEMA_VERSION = 2


def package_versions() -> dict[str, str]:
    """Versions of Python and the numerical packages the result depends on."""
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for name in ("calib", "numpy", "scipy", "casadi", "matplotlib"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "unknown"
    return out


def _atomic_write(path: Path, writer) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        writer(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


_ARRAY_FIELDS = ("p_nominal", "p_hat", "lower", "upper", "scale", "cov_p", "std_p", "singular_values", "V",
                 "sigma_theta", "retained", "theta_hat", "cov_theta", "theta_nominal_linearization",
                 "correlation", "crb_std", "observability", "measured", "sigma", "model_before",
                 "model_after", "status_before", "status_after", "alpha_seen", "eta_seen", "noise_sigma", "prior_std", "cov_frozen",
                 "multiple_roots")
_OPTIONAL_ARRAYS = ("gain", "cov_alias")


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
    """Everything a calibration produced.

    Array attributes (shapes; n = n_params, m = n_points, c = n_channels, r = n_retained)
    -----------------------------------------------------------------------------------
    p_nominal, p_hat, lower, upper, scale : (n,)
        Nominal and estimated parameters, effective bounds and scales.
    cov_p, std_p : (n, n), (n,)
        Covariance / standard deviation of p̂, including the prior variance of the directions
        the truncation froze (:func:`calib.identifiability.frozen_aware_covariance`).
    cov_frozen : (n, n)
        The frozen directions' part of ``cov_p`` (what the prior, not the data, says).
    prior_std : (n,)
        Prior 1-σ of each parameter [parameter unit].
    singular_values, V, sigma_theta, retained : (n,), (n, n), (n,), (n,) bool
        SVD of the whitened scaled sensitivities at p̂ (docs/theory.md, Estimation).
    theta_hat, cov_theta : (r,), (r, r)
        Retained θ = V_IDᵀ p̃ and their covariance [scale units].
    correlation, crb_std : (n, n), (n,)
        Cramér–Rao correlation matrix and standard deviations of the full nodal problem.
    observability : (n,)
        Fraction of each scaled parameter inside the retained subspace.
    measured, sigma, model_before, model_after : (m, c)
    status_before, status_after : (m,) int
    alpha_seen, eta_seen : (k,)
        (α, η) the converged operating points see at p̂ (empty if the model does not report it).
    noise_sigma : (c,)
        Per-channel noise used in the final estimate.
    multiple_roots : (m,) bool
        Points where the model reported several roots of its equations (native BEM).

    Other attributes
    ----------------
    truncation : dict
        The automatic-truncation curve (:class:`calib.truncation.TruncationCurve`), empty
        for an explicit σ̄.
    confounding : dict
        Per non-field parameter, its information shared with the others
        (:func:`calib.identifiability.confounding`).
    model_spec : dict or None
        What :func:`calib.models.registry.build_model` needs to rebuild the model (predictions).
    checks : dict
        Named statements added after the run (e.g. coverage of a known truth in a synthetic run).
    fit_scale : float
        Factor on the covariance of the retained θ from the misfit, max(1, χ²/dof) with
        ``scale_by_fit`` and a stated noise (1: not scaled) [-].
    aliasing_chi2 : float
        The χ² after that the field between the nodes is expected to add on average (prior
        average, :mod:`calib.parametrizations.aliasing`; 0 where that term does not apply) [-].
    aliasing_note : str
        Why the bands leave that term out ('' when it is in, or when there is no correction
        field or nothing retained for it to act on).
    curvature : dict
        The frozen directions' prior propagated through the model's curvature to the retained
        θ (:func:`calib.identifiability.frozen_curvature_covariance`): ``samples`` drawn (0: the
        term is left out), ``used``, ``samples_with_failed_points``, and its variance against
        the noise part per retained θ, ``variance_ratio_mean`` and ``variance_ratio_max`` [-];
        empty when nothing was frozen or nothing retained.
    prior_check : dict
        The data's estimate of the correction field's prior amplitude
        (:class:`calib.prior_check.PriorCheck` as a dict: ``amplitude``, ``lower``, ``upper``,
        ``confidence``, ``verdict``, ``between_nodes``, ``log_lr_at_stated``, ...); empty without a
        correction field or with the check off; ``{"failed": message}`` when it could not be
        computed (the calibration's result stands).
    fold_directions : list of dict
        Retained θ that a point with several roots of the BEM equations determines (more than
        half of the θ's information, :func:`calib.identifiability.fold_dominated_directions`):
        ``point``, ``theta`` (1-based), ``share``, ``sensitivity_ratio`` and the σ along the
        direction before and after its prior variance was added, ``sigma_before``,
        ``sigma_after`` [scale units]. Empty when there is none.
    """

    parameters: list[dict]
    channels: list[str]
    channel_units: list[str]
    conditions: dict[str, np.ndarray]
    settings: dict
    p_nominal: np.ndarray
    p_hat: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    cov_p: np.ndarray
    std_p: np.ndarray
    singular_values: np.ndarray
    V: np.ndarray
    sigma_theta: np.ndarray
    retained: np.ndarray
    theta_hat: np.ndarray
    cov_theta: np.ndarray
    theta_nominal_linearization: np.ndarray
    correlation: np.ndarray
    crb_std: np.ndarray
    observability: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray
    model_before: np.ndarray
    model_after: np.ndarray
    status_before: np.ndarray
    status_after: np.ndarray
    alpha_seen: np.ndarray
    eta_seen: np.ndarray
    noise_sigma: np.ndarray
    sigma_bar: float
    verdicts: list[dict]
    history: list[dict]
    status: str
    message: str
    failures: dict
    chi2_before: float
    chi2_after: float
    rotor_radius: float | None = None
    polar_bands: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    versions: dict = field(default_factory=package_versions)
    wall_time: float = 0.0
    name: str = "calibration"
    prior_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov_frozen: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    multiple_roots: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    truncation: dict = field(default_factory=dict)
    confounding: dict = field(default_factory=dict)
    model_spec: dict | None = None
    checks: dict = field(default_factory=dict)
    fit_scale: float = 1.0
    aliasing_chi2: float = 0.0
    aliasing_note: str = ""
    curvature: dict = field(default_factory=dict)
    prior_check: dict = field(default_factory=dict)
    fold_directions: list = field(default_factory=list)
    tightening: dict = field(default_factory=dict)
    gain: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    cov_alias: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    # ------------------------------------------------------------------ derived
    def parameters_frame(self):
        """The parameters, estimates, σ, priors and verdicts as a DataFrame (:func:`calib.frames.parameters_frame`)."""
        from calib.frames import parameters_frame
        return parameters_frame(self)

    def points_frame(self):
        """Per point: measured, nominal, calibrated, residual, as a DataFrame (:func:`calib.frames.points_frame`)."""
        from calib.frames import points_frame
        return points_frame(self)

    @property
    def estimator(self) -> str:
        """``"map"`` or ``"truncated"`` (results written before the setting existed: truncated)."""
        return str(self.settings.get("estimator", "truncated"))

    @property
    def n_params(self) -> int:
        return int(self.p_hat.size)

    @property
    def n_retained(self) -> int:
        return int(np.count_nonzero(self.retained))

    @property
    def n_points(self) -> int:
        return int(self.measured.shape[0])

    @property
    def dof(self) -> int:
        """Degrees of freedom of χ² after: converged residuals minus retained parameters."""
        ok = self.status_after == 0
        return int(ok.sum() * len(self.channels) - self.n_retained)

    @property
    def dof_before(self) -> int:
        """Degrees of freedom of χ² before: converged residuals of the nominal model (nothing fitted)."""
        return int((self.status_before == 0).sum() * len(self.channels))

    @property
    def chi2_per_dof_before(self) -> float:
        return self.chi2_before / max(self.dof_before, 1)

    @property
    def chi2_per_dof_after(self) -> float:
        return self.chi2_after / max(self.dof, 1)

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

        out = {"chi2_before": self.chi2_before, "dof_before": self.dof_before,
               "chi2_per_dof_before": self.chi2_per_dof_before,
               "p_value_before": float(stats.chi2.sf(self.chi2_before, max(self.dof_before, 1))),
               "chi2_after": self.chi2_after, "dof_after": self.dof, "chi2_per_dof_after": self.chi2_per_dof_after,
               "p_value_after": float(stats.chi2.sf(self.chi2_after, max(self.dof, 1)))}
        per = {}
        rb, ra = self.rms("before"), self.rms("after")
        for i, c in enumerate(self.channels):
            row = {}
            for which, model, status in (("before", self.model_before, self.status_before),
                                         ("after", self.model_after, self.status_after)):
                ok = status == 0
                w = (self.measured[ok, i] - model[ok, i]) / self.sigma[ok, i]
                row[f"chi2_per_point_{which}"] = float(np.mean(w ** 2)) if w.size else float("nan")
            row["rms_before"], row["rms_after"] = rb[c], ra[c]
            per[c] = row
        out["per_channel"] = per
        ok = self.status_after == 0
        w = np.where(ok[:, None], (self.measured - np.where(ok[:, None], self.model_after, 0.0)) / self.sigma, 0.0)
        order = np.argsort(-np.abs(w), axis=None)[:n_worst]
        out["worst"] = [{"point": int(k // w.shape[1]), "channel": self.channels[int(k % w.shape[1])],
                         "whitened_residual": float(w.flat[k]),
                         "conditions": {n: float(v[k // w.shape[1]]) for n, v in self.conditions.items()}}
                        for k in order if ok[k // w.shape[1]]]
        return out

    def predict(self, conditions, model=None, confidence: float = 0.95) -> "Prediction":
        """Model outputs at new conditions with intervals from the estimate's covariance.

        The variance of each output is g Cov(p̂) gᵀ with g its row of the model Jacobian at p̂
        and Cov(p̂) the covariance including the frozen directions (docs/theory.md, Predictions): an interval of
        the *model output*, not of a new measurement (add the noise σ for that).

        Parameters
        ----------
        conditions : OperatingConditions
        model : ForwardModel, optional
            Default: rebuilt from ``model_spec``.
        confidence : float

        Returns
        -------
        Prediction
        """
        from scipy import stats

        if model is None:
            model = self.rebuild_model()
        names = [c.name for c in model.channels]
        missing = [c for c in self.channels if c not in names]
        if missing:
            raise InputError(f"model lacks channel(s) {', '.join(missing)}", self.name, field="channels")
        idx = [names.index(c) for c in self.channels]
        ev, G = model.jacobian(self.p_hat, conditions)
        G = G[:, idx, :]
        rep, representation = self._field_between_nodes(model, conditions, ev, G, idx)
        cov = self.cov_p if rep is None else self.cov_p - self.cov_alias
        var = np.einsum("kcj,jl,kcl->kc", np.nan_to_num(G), cov, np.nan_to_num(G))
        if rep is not None:
            var = var + rep
        std = np.sqrt(np.maximum(var, 0.0))
        z = float(stats.norm.ppf(0.5 * (1 + confidence)))
        values = ev.values[:, idx]
        std = np.where(ev.ok[:, None], std, np.nan)
        extras = ev.extras or {}
        envelope = envelope_of(self.conditions, self.rotor_radius, conditions.as_dict(), extras.get("alpha_deg"),
                               extras.get("eta"), self.alpha_seen, self.eta_seen) if self.conditions else []
        return Prediction(tuple(self.channels), tuple(self.channel_units), values, std, values - z * std,
                          values + z * std, ev.status.copy(), tuple(ev.messages), confidence, tuple(envelope),
                          representation)

    def _field_between_nodes(self, model, conditions, ev, G, idx) -> tuple[np.ndarray | None, str]:
        """The variance of each predicted output [channel unit²] from the correction field the nodes do
        not carry (between them, and beyond their range, where it is the prior's), net of what the
        estimate took up of it at the calibration points, and a sentence on it.

        With the smooth-field prior, the field is f = Σ N_i f_i + δ, δ ~ N(0, Σ_δ) on a fine grid
        (:mod:`calib.parametrizations.aliasing`). A predicted output y = g p + w δ and the estimate
        p̂ = p + K(W_cal δ + noise) (K = ``gain``, the MAP's linear response to the whitened data),
        so its error has the δ-part (g K W_cal − w) δ, of variance (gK W_cal − w) Σ_δ (gK W_cal − w)ᵀ;
        that replaces the nodal term g Cov_alias gᵀ in g Cov(p̂) gᵀ. Beyond the nodes the hats vanish
        and δ is the whole field: the correction reverts to the prior's band there. None when the
        result has no gain (truncated estimator, no field) or the model cannot be refined (an FMU).
        """
        st = self.settings
        if not self.gain.size or not self.prior_std.size:
            return None, ("the bands leave out the field between and beyond the correction nodes (estimator "
                          f"{st.get('estimator', 'truncated')!r} records no gain)")
        if not model.capabilities.refinable or not st.get("representation_error", True) \
                or not st.get("prior_correlation", 0.0) > 0:
            return None, "the bands leave out the field between and beyond the correction nodes (off, or not refinable)"
        from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities
        from calib.types import OperatingConditions

        field_ = model.correction_field()
        a_new, e_new = field_.seen(ev)
        cal = OperatingConditions(**self.conditions)
        a_all, e_all = np.concatenate([a_new, self.alpha_seen]), np.concatenate([e_new, self.eta_seen])
        ok_cal = self.status_after == 0
        ones = np.ones((len(conditions), len(idx)))
        fs_new = fine_sensitivities(model, self.p_hat, conditions, ones, idx, ev.ok, a_all, e_all)
        fs_cal = fine_sensitivities(model, self.p_hat, cal, self.sigma, idx, ok_cal, a_all, e_all)
        gG = np.nan_to_num(G).reshape(-1, G.shape[-1]) * self.scale       # ∂y/∂p̃ per output row
        A = gG @ (self.gain @ fs_cal.W) - fs_new.W
        var = discrepancy_propagated(A, field_, fs_new, self.prior_std, float(st["prior_correlation"]), diagonal=True)
        return var.reshape(G.shape[:2]), ("the bands include the field between and beyond the correction nodes "
                                          "(the prior's, net of what the calibration points determined)")

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
        json_path = getattr(self, "_json_path", None)    # set by load_result
        folder = None if json_path is None else json_path.parent
        where = str(json_path) if json_path is not None else self.name
        if not self.model_spec:
            raise InputError("this result recorded no model spec to rebuild its model; pass model=", where,
                             field="model_spec")
        from calib.models.registry import build_model

        return build_model(self.model_spec, base_dir=folder, source=f"{where}: model_spec")

    @property
    def parameter_objects(self) -> tuple[Parameter, ...]:
        keys = {f.name for f in fields(Parameter)}
        return tuple(Parameter(**{k: v for k, v in d.items() if k in keys}) for d in self.parameters)

    @property
    def layout(self) -> NodeLayout:
        return node_layout(self.parameter_objects)

    def verdict_counts(self) -> dict[str, int]:
        out = {"identified": 0, "poorly observable": 0, "at bound": 0, "confounded": 0}
        for v in self.verdicts:
            out[v["verdict"]] = out.get(v["verdict"], 0) + 1
        return out

    def rms(self, which: str = "after") -> dict[str, float]:
        """Per-channel RMS of the residual (converged points) [channel units]."""
        model = self.model_after if which == "after" else self.model_before
        status = self.status_after if which == "after" else self.status_before
        ok = status == 0
        return {c: float(np.sqrt(np.mean((self.measured[ok, i] - model[ok, i]) ** 2)))
                for i, c in enumerate(self.channels)}

    def tip_speed_ratio(self) -> np.ndarray | None:
        """λ = ΩR/V of each point [-] (None when the rotor radius is unknown)."""
        if not self.rotor_radius:
            return None
        return self.conditions["rotor_speed"] * np.pi / 30.0 * self.rotor_radius / self.conditions["wind_speed"]

    def eigenshapes(self, alpha_deg, eta, modes=None):
        """Lift and drag eigenshapes (n_modes, n_eta, n_alpha) of the given modes (default: retained)."""
        if modes is None:
            modes = np.flatnonzero(self.retained)
        return eigenshapes(self.V, self.layout, alpha_deg, eta, modes)

    def summary(self) -> str:
        """A few plain lines with the key numbers."""
        counts = self.verdict_counts()
        how = (f"chosen by {self.truncation.get('criterion', 'K-fold')} cross-validation over operating points"
               if self.truncation else "set")
        if self.estimator == "map":
            kept = (f"  parameters {self.n_params}, MAP estimate under the stated prior; the data determine "
                    f"{self.n_retained} directions better than the prior (s > 1)")
        else:
            kept = f"  parameters {self.n_params}, retained {self.n_retained} (sigma_bar = {self.sigma_bar:.3g}, {how})"
        lines = [f"{self.name}: {self.status} ({self.message})", kept,
                 f"  chi2/dof before {self.chi2_per_dof_before:.3g} (dof {self.dof_before}), after "
                 f"{self.chi2_per_dof_after:.3g} (dof {self.dof})",
                 "  verdicts: " + ", ".join(f"{k} {v}" for k, v in counts.items()),
                 "  failed model points: " + ", ".join(f"{k} {v}" for k, v in self.failures.items())]
        if "second_retained" in self.truncation:
            lines.append("  " + second_start_sentence(self.truncation))
        if self.prior_check.get("failed"):
            lines.append(f"  prior check: failed ({self.prior_check['failed']})")
        elif self.prior_check:
            pc = self.prior_check
            lines.append(f"  prior check: field amplitude {pc['amplitude']:.2g} x stated "
                         f"({100 * pc['confidence']:.0f} % interval {pc['lower']:.2g}-{pc['upper']:.2g}), "
                         f"{pc['verdict']}")
        if self.fold_directions:
            lines.append("  " + fold_sentence(self.fold_directions, self.conditions, self.tip_speed_ratio()))
        rb, ra = self.rms("before"), self.rms("after")
        for c in self.channels:
            lines.append(f"  rms {c}: {rb[c]:.4g} -> {ra[c]:.4g}")
        return "\n".join(lines)

    # ------------------------------------------------------------------ i/o
    def to_json_dict(self) -> dict:
        scalars = {}
        for f in fields(self):
            if f.name in _ARRAY_FIELDS + _OPTIONAL_ARRAYS or f.name in ("conditions", "polar_bands", "truncation"):
                continue
            scalars[f.name] = getattr(self, f.name)
        scalars["schema_version"] = SCHEMA_VERSION
        scalars["summary"] = {"n_params": self.n_params, "n_retained": self.n_retained, "dof": self.dof,
                              "goodness_of_fit": self.goodness_of_fit(),
                              "truncation": {"criterion": f"{self.truncation.get('criterion')} cross-validation",
                                             "chosen": self.truncation.get("chosen"),
                                             "sigma_bar": self.sigma_bar} if self.truncation else
                              {"criterion": "threshold", "sigma_bar": self.sigma_bar},
                              "verdict_counts": self.verdict_counts()}
        return _jsonable(scalars)

    def save(self, out_dir: str | Path, stem: str = "result") -> tuple[Path, Path]:
        """Write ``<stem>.json`` and ``<stem>.npz`` into ``out_dir`` (atomically)."""
        out_dir = Path(out_dir)
        jpath, npath = out_dir / f"{stem}.json", out_dir / f"{stem}.npz"
        text = json.dumps(self.to_json_dict(), indent=1, allow_nan=True)

        def write_json(tmp):
            with open(tmp, "w", encoding="utf-8") as f:
                f.write(text)
                f.flush()
                os.fsync(f.fileno())    # the blocks are on disk before the rename makes the name final

        _atomic_write(jpath, write_json)
        arrays = {k: np.asarray(getattr(self, k)) for k in _ARRAY_FIELDS + _OPTIONAL_ARRAYS}
        arrays.update({f"conditions__{k}": np.asarray(v) for k, v in self.conditions.items()})
        arrays.update({f"polar__{k}": np.asarray(v) for k, v in self.polar_bands.items()})
        arrays.update({f"truncation__{k}": np.asarray(v) for k, v in self.truncation.items()})

        def write_npz(tmp):
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **arrays)
                f.flush()
                os.fsync(f.fileno())

        _atomic_write(npath, write_npz)
        return jpath, npath


@dataclass(frozen=True, eq=False)
class Prediction:
    """Model outputs at new conditions with their intervals.

    Attributes
    ----------
    channels, units : tuple of str
    values, std, lower, upper : ndarray, shape (n_points, n_channels)
        Prediction, its 1-σ and the two-sided interval at ``confidence`` [channel units];
        NaN where ``status != 0``.
    status : ndarray of int, shape (n_points,)
    messages : tuple of str
    confidence : float
    envelope : tuple of str
        Per point, "" inside the calibration envelope, else what lies outside it
        (:func:`calib.envelope.envelope_of`): an extrapolation.
    representation : str
        Whether the intervals include the correction field between and beyond the nodes
        (:meth:`CalibrationResult._field_between_nodes`).
    """

    channels: tuple
    units: tuple
    values: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    status: np.ndarray
    messages: tuple
    confidence: float
    envelope: tuple = ()
    representation: str = ""

    def to_dataframe(self, conditions):
        """One row per point with its ``conditions`` (:func:`calib.frames.prediction_frame`)."""
        from calib.frames import prediction_frame
        return prediction_frame(conditions, self)

    @property
    def outside(self) -> np.ndarray:
        """True where the point lies outside the calibration envelope."""
        return np.array([bool(e) for e in self.envelope], bool) if self.envelope else \
            np.zeros(self.values.shape[0], bool)


def _jsonable(x, fallback=None):
    """``x`` with numpy scalars and arrays, paths and enums turned into JSON types, recursively;
    any other object is kept, or passed through ``fallback`` (e.g. ``str``) when given."""
    if isinstance(x, dict):
        return {str(k): _jsonable(v, fallback) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v, fallback) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist(), fallback)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, enum.Enum):
        return x.value
    if fallback is not None and not (isinstance(x, (str, int, float, bool)) or x is None):
        return fallback(x)
    return x


def load_result(path: str | Path, stem: str = "result") -> CalibrationResult:
    """Load a result written by :meth:`CalibrationResult.save`.

    Parameters
    ----------
    path : str or Path
        The output directory, or the ``.json`` / ``.npz`` file.
    """
    path = Path(path)
    if path.is_dir():
        jpath, npath = path / f"{stem}.json", path / f"{stem}.npz"
    else:
        jpath, npath = path.with_suffix(".json"), path.with_suffix(".npz")
    for p in (jpath, npath):
        if not p.is_file():
            raise InputError("result file not found", p)
    data = json.loads(jpath.read_text())
    if data.get("schema_version") != SCHEMA_VERSION:
        raise InputError(f"unsupported result schema {data.get('schema_version')!r}, expected {SCHEMA_VERSION}",
                         jpath, field="schema_version")
    data.pop("schema_version")
    data.pop("summary", None)
    with np.load(npath) as z:
        arrays = {k: z[k] for k in z.files}
    kwargs = {k: arrays[k] for k in _ARRAY_FIELDS}
    kwargs.update({k: arrays[k] for k in _OPTIONAL_ARRAYS if k in arrays})     # (results written before them)
    kwargs["retained"] = kwargs["retained"].astype(bool)
    kwargs["conditions"] = {k.split("__", 1)[1]: v for k, v in arrays.items() if k.startswith("conditions__")}
    kwargs["polar_bands"] = {k.split("__", 1)[1]: v for k, v in arrays.items() if k.startswith("polar__")}
    kwargs["truncation"] = {k.split("__", 1)[1]: (v.item() if v.ndim == 0 else v)
                            for k, v in arrays.items() if k.startswith("truncation__")}
    kwargs["multiple_roots"] = kwargs["multiple_roots"].astype(bool)
    names = {f.name for f in fields(CalibrationResult)}
    kwargs.update({k: v for k, v in data.items() if k in names})
    result = CalibrationResult(**kwargs)
    result._json_path = jpath.resolve()     # rebuild_model names it and looks for relocated rotor files beside it
    return result
