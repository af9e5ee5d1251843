"""The discrepancy workflow: find where model and measurements disagree, name the missing
effect, add it, show the gap shrink (docs/theory.md, Discrepancy workflow).

Steps
-----
1. **Find**: the nominal model's whitened residuals r = (z − y)/σ; the χ² test (χ²/N and its
   p-value) says whether the model is consistent with the noise; per channel and against
   tip-speed ratio, pitch and wind speed the residuals say where it is not.
2. **Localize**: the SVD calibration of the correction field (:class:`calib.calibration.Calibrator`,
   automatic truncation) says which (α, η) region of the polars would have to change; with
   ``noise = "ml"`` it also gives the noise σ the later steps use.
3. **Name**: every candidate effect of :data:`calib.effects.EFFECTS` (but the correction field)
   is switched into the model on its own and fitted by maximum likelihood (all its few
   parameters free); an effect with several model forms (rotational augmentation: Snel,
   Du & Selig, Chaviaropoulos & Hansen) enters once per form, and its best form names it. Candidates are compared with the model without them by

   - the likelihood-ratio statistic Λ = χ²_base − χ²_candidate, χ²(k)-distributed with k the
     candidate's parameter count when the candidate adds nothing (Wilks 1938); significant
     when its p-value is below ``significance`` divided by the number of candidates
     (Bonferroni);
   - the Bayesian information criterion BIC = χ² + k ln N and the weights
     w ∝ exp(−½ BIC) over the candidates and "none" (Schwarz 1978; Burnham & Anderson 2002);
   - the agreement of the candidate's change of the outputs with the localized correction's
     change (correlation of the two whitened output changes): an effect that explains the data
     moves the outputs the way the free correction field does.

   The best significant candidate is named when no other significant candidate is within
   ``ambiguity_bic`` of its BIC; otherwise the result is ``ambiguous`` and names both. With
   nothing significant the result is ``none``. After naming one effect, it is added with its
   fitted parameters and, while the model is still inconsistent with the noise (χ² test at
   ``significance``), the remaining candidates are tried on top (up to ``max_effects``).

   A fitted parameter within :data:`AT_BOUND_TOLERANCE` (10⁻³) of its scale of a bound is
   **at bound** (:func:`bound_side`): the candidate table and the verdict say so, since its
   value is the bound the data push against, not an estimate. A named effect joins the next
   round with its fitted values clipped into their bounds (an estimate on a bound may end a
   few ulp past it). A round that fails (a :class:`~calib.errors.CalibError`) is recorded
   with verdict ``failed``; the naming stops there and the earlier rounds' findings stand
   (``Diagnosis.failure`` says what failed), as when the recalibration fails.
4. **Add** the named effect(s) with their fitted parameters; **recalibrate** the correction
   field on top for what remains.
5. **Show** χ²/dof and per-channel RMS before (nominal), with the named effect(s), and after
   the recalibration.

References
----------
S.S. Wilks, The large-sample distribution of the likelihood ratio for testing composite
hypotheses, Ann. Math. Stat. 9 (1938) 60-62.
G. Schwarz, Estimating the dimension of a model, Ann. Stat. 6 (1978) 461-464.
K.P. Burnham, D.R. Anderson, Model Selection and Multimodel Inference, 2nd ed., Springer (2002).
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models from
rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy import stats

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.effects import EFFECTS, make_effect
from calib.errors import CalibError, InputError
from calib.measurements import Measurements
from calib.models.bem_model import BemModel
from calib.diagnosis.separation import envelope_words, probe_conditions, separating_probes
from calib.types import CONDITION_FIELDS, OperatingConditions
from calib.words import p_is

#: Effects the native BEM can name (the correction field is the localizer, not a candidate).
NAMEABLE = tuple(n for n in EFFECTS if n != "correction_field")

#: A fitted parameter is "at bound" when it lies within this fraction of its scale of a bound
#: (or beyond it by round-off): the rule of :func:`calib.identifiability.parameter_verdicts`.
AT_BOUND_TOLERANCE = 1e-3


#: Default model-form tolerance [-]: the RMS relative difference between calib's native BEM and an
#: independent code, WISDEM's CCBlade 4.2.9, on the same rotor and polars (NREL 5-MW, 63 operating
#: points of the out-of-family battery, no effect, no noise; the larger of the rigid and the
#: tilted/coned set-up; benchmarks/bench_oof_battery.py, measured 2026-11-25), rounded up. The
#: difference is CCBlade's smoothing spline on the polars (below 5e-5 with calib's polar_smoothing
#: of the same spline). root_flap_moment takes the hub flap moment's (the same loads about another
#: point); other channels not measured take the largest ("default").
MODEL_FORM_TOLERANCE = {"power": 0.0097, "torque": 0.0097, "thrust": 0.0024, "hub_flap_moment": 0.0029,
                        "root_flap_moment": 0.0029, "default": 0.0097}

#: Noise models whose σ the calibration estimates from the residuals (no global test against it).
ESTIMATED_NOISE = ("ml", "relative_ml")

#: Relative χ² increase a recalibration may show before it is rejected (round-off of the sums) [-].
RECALIBRATION_SLACK = 1e-9


@dataclass(frozen=True)
class DiagnosisSettings:
    """Settings of :func:`diagnose`.

    Parameters
    ----------
    candidates : tuple of str or None
        Effects to try (default: every effect of the registry but the correction field).
    candidate_options : dict
        Options per candidate, e.g. ``{"rotational_augmentation": {"variant": "snel"}}``.
    max_effects : int
        How many effects may be named in sequence.
    significance : float
        Family-wise level of the likelihood-ratio tests (Bonferroni over the candidates).
    ambiguity_bic : float
        Two significant candidates closer than this in BIC are not told apart by the
        information criterion.
    ambiguity_pattern : float
        ... nor by their pattern when their agreements with the localized correction differ
        by less than this [-]; then the verdict is ``ambiguous``, with the measurement that
        would separate them (:mod:`calib.diagnosis.separation`). When the patterns differ by more, the
        candidate whose pattern agrees better is named.
    recalibrate : bool
        Re-run the correction-field calibration on top of the named effects.
    model_form_tolerance : float or dict
        Relative model-form error allowed to the nominal model in the naming step [-]: a
        number for every channel, or a table channel (or spanwise group ``cn``) -> fraction
        (``"default"`` for the others). It enters the naming step's noise,
        σ² + (tolerance · |y|)², and a candidate is named only when its change of the outputs
        exceeds it somewhere (practical significance, reported as an effect size). 0 leaves
        both out. Default :data:`MODEL_FORM_TOLERANCE`.
    """

    candidates: tuple | None = None
    candidate_options: dict = field(default_factory=dict)
    max_effects: int = 2
    significance: float = 0.01
    ambiguity_bic: float = 6.0
    ambiguity_pattern: float = 0.1
    recalibrate: bool = True
    model_form_tolerance: float | dict = field(default_factory=lambda: dict(MODEL_FORM_TOLERANCE))

    def tolerance_of(self, channels: Sequence[str]) -> np.ndarray:
        """The model-form tolerance of each channel [-] (see the class docstring)."""
        tol = self.model_form_tolerance
        if not isinstance(tol, dict):
            return np.full(len(channels), float(tol))
        group = {c: c.split("@")[0] for c in channels}      # cn@0.30 takes "cn" when given
        return np.array([float(tol.get(c, tol.get(group[c], tol.get("default", 0.0)))) for c in channels])

    def validate(self, source: str = "DiagnosisSettings", prefix: str = "",
                 valid: Sequence[str] = NAMEABLE) -> "DiagnosisSettings":
        """Check every setting (``valid``: the candidate names of the model family)."""
        def need(ok: bool, key: str, what: str):
            if not ok:
                raise InputError(f"must be {what}, got {getattr(self, key)!r}", source, field=f"{prefix}{key}")

        def number(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool)

        need(self.candidates is None or (isinstance(self.candidates, (tuple, list))
                                         and all(isinstance(c, str) for c in self.candidates)),
             "candidates", "an array of effect names")
        need(isinstance(self.candidate_options, dict) and all(isinstance(v, dict)
                                                               for v in self.candidate_options.values()),
             "candidate_options", "a table of tables (effect -> options)")
        need(isinstance(self.max_effects, int) and not isinstance(self.max_effects, bool), "max_effects",
             "an integer")
        need(number(self.significance), "significance", "a number")
        need(number(self.ambiguity_bic), "ambiguity_bic", "a number")
        need(number(self.ambiguity_pattern) and 0 <= self.ambiguity_pattern <= 2, "ambiguity_pattern",
             "a number in [0, 2] (a difference of correlations)")
        need(isinstance(self.recalibrate, bool), "recalibrate", "true or false")
        tol = self.model_form_tolerance
        values = list(tol.values()) if isinstance(tol, dict) else [tol]
        need(all(number(v) and 0 <= v < 1 for v in values), "model_form_tolerance",
             "a fraction in [0, 1) or a table channel -> fraction")
        names = self.candidates if self.candidates is not None else valid
        unknown = [c for c in names if c not in valid]
        if unknown:
            raise InputError(f"unknown candidate effect(s) {', '.join(unknown)}; valid: {', '.join(valid)}",
                             source, field=f"{prefix}candidates")
        if not 0 < self.significance < 1:
            raise InputError(f"must be in (0, 1), got {self.significance!r}", source, field=f"{prefix}significance")
        if self.max_effects < 0:
            raise InputError(f"must be >= 0, got {self.max_effects!r}", source, field=f"{prefix}max_effects")
        if not self.ambiguity_bic >= 0:
            raise InputError(f"must be >= 0, got {self.ambiguity_bic!r}", source, field=f"{prefix}ambiguity_bic")
        return self


@dataclass
class CandidateFit:
    """One candidate effect fitted by maximum likelihood on top of the current model."""

    name: str
    parameters: list          # [{name, value, std, unit, nominal}]
    chi2: float
    n_params: int
    loglik: float
    bic: float
    lr_statistic: float
    p_value: float
    significant: bool
    weight: float = 0.0
    pattern_agreement: float = float("nan")
    status: str = ""
    spec: dict = field(default_factory=dict)
    model_values: np.ndarray | None = None
    effect: str = ""
    at_bound: list = field(default_factory=list)    # names of the parameters at a bound
    effect_size: float = float("nan")   # largest relative change of an output [-] (effect_size())
    effect_text: str = ""               # the same in words: "-2.1 % power at 7.3 m/s (tolerance 1 %)"
    start: str = ""                     # the second start, when one ran (_fit_task): "second start kept (...)"
    p_hat: np.ndarray | None = None     # every fitted parameter (base effects' too) [parameter units]

    def bound_phrase(self) -> str:
        """The parameters at a bound in words ("" when none): their value is the bound, not an estimate."""
        at = [q for q in self.parameters if q.get("at_bound")]
        if not at:
            return ""
        unit = {q["name"]: "" if q["unit"] in ("", "-") else f" {q['unit']}" for q in at}
        return "at bound: " + ", ".join(f"{q['name']} = {q[q['at_bound']]:.4g}{unit[q['name']]} ({q['at_bound']} bound)"
                                        for q in at)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d.pop("model_values")
        d.pop("p_hat")
        return d


@dataclass
class Diagnosis:
    """What :func:`diagnose` found (``to_dict`` is ``diagnosis.json``)."""

    effect: str
    effects: list
    rounds: list                       # per naming round: {"candidates": [CandidateFit], "verdict": ...}
    before: dict
    with_effects: dict
    after: dict
    find: dict
    localization: object               # CalibrationResult of the correction field alone
    recalibration: object              # CalibrationResult on top of the named effects (or None)
    channels: list
    measured: np.ndarray
    sigma: np.ndarray
    conditions: dict
    model_before: np.ndarray
    model_with_effects: np.ndarray
    model_after: np.ndarray | None
    rotor_radius: float
    wall_time: float = 0.0
    notes: list = field(default_factory=list)
    failure: str = ""                  # why the diagnosis stopped early ("" when it ran to the end)
    setup: list = field(default_factory=list)   # calib.setup_statement.SetupItem: the set-up in force

    @property
    def candidates(self) -> list:
        """The first round's candidates (the comparison against the nominal model)."""
        return self.rounds[0]["candidates"] if self.rounds else []

    def to_dict(self) -> dict:
        return {"effect": self.effect, "effects": self.effects,
                "candidates": [c.to_dict() for c in self.candidates],
                "rounds": [{"base": r["base"], "verdict": r["verdict"], "reason": r["reason"],
                            **{k: r[k] for k in ("ambiguous", "separate") if k in r},
                            "candidates": [c.to_dict() for c in r["candidates"]]} for r in self.rounds],
                "before": self.before, "with_effects": self.with_effects, "after": self.after,
                "find": self.find, "channels": self.channels, "wall_time": self.wall_time, "notes": self.notes,
                "failure": self.failure, "setup": [i.as_dict() for i in self.setup],
                "localization": {"n_retained": self.localization.n_retained,
                                 "chi2_per_dof_after": self.localization.chi2_per_dof_after,
                                 "status": self.localization.status},
                "recalibration": None if self.recalibration is None else {
                    "n_retained": self.recalibration.n_retained, "status": self.recalibration.status,
                    "chi2_per_dof_after": self.recalibration.chi2_per_dof_after}}


# ----------------------------------------------------------------------------- figures of merit
#: Points whose |output| is at least this fraction of the channel's largest count in effect sizes.
EFFECT_SIZE_USABLE = 0.1


def effect_size(values: np.ndarray, base: np.ndarray, tolerance: np.ndarray, channels: Sequence[str],
                wind_speed: np.ndarray) -> tuple[float, str, bool]:
    """How much a candidate changes the outputs, against the model-form tolerance.

    Parameters
    ----------
    values, base : ndarray, shape (n_points, n_channels)
        The outputs with the candidate and without it [channel units].
    tolerance : ndarray, shape (n_channels,)
        Relative model-form tolerance per channel [-].
    channels : sequence of str
    wind_speed : ndarray, shape (n_points,)
        Named in the words [m/s].

    Returns
    -------
    size : float
        The largest relative change (values − base) / |base| over the points where |base|
        is at least :data:`EFFECT_SIZE_USABLE` of the channel's largest [-], in the channel
        where it is largest against the tolerance.
    words : str
        E.g. ``"-2.1 % power at 7.3 m/s (tolerance 1 %)"`` (the wind speed of that point).
    exceeds : bool
        Whether that change exceeds the channel's tolerance (always, with tolerance 0 and a
        change).
    """
    best = (-1.0, 0.0, "", 0.0, np.nan)
    for j, c in enumerate(channels):
        b = np.abs(base[:, j])
        ok = np.isfinite(values[:, j]) & np.isfinite(base[:, j]) & (b >= EFFECT_SIZE_USABLE * np.nanmax(b, initial=0))
        ok &= b > 0
        if not ok.any():
            continue
        rel = (values[ok, j] - base[ok, j]) / b[ok]
        k = int(np.argmax(np.abs(rel)))
        score = abs(rel[k]) / tolerance[j] if tolerance[j] > 0 else (np.inf if rel[k] != 0 else 0.0)
        if score > best[0]:
            best = (score, float(rel[k]), c, float(tolerance[j]), float(wind_speed[ok][k]))
    score, rel, c, tol, v = best
    if score < 0:
        return float("nan"), "no usable point", False
    words = f"{100 * rel:+.2g} % {c} at {v:.3g} m/s" + (f" (tolerance {100 * tol:.2g} %)" if tol else "")
    return abs(rel), words, bool(score > 1.0)


def gap(measured: np.ndarray, model: np.ndarray, sigma: np.ndarray, channels: Sequence[str], n_fitted: int = 0) -> dict:
    """χ², χ²/dof (dof = N − n_fitted), p-value and per-channel RMS of measured − model."""
    ok = np.all(np.isfinite(model), axis=1)
    w = (measured[ok] - model[ok]) / sigma[ok]
    chi2 = float(np.sum(w ** 2))
    dof = max(int(w.size) - int(n_fitted), 1)
    rms = {c: float(np.sqrt(np.mean((measured[ok, j] - model[ok, j]) ** 2))) for j, c in enumerate(channels)}
    chi2_ch = {c: float(np.mean(w[:, j] ** 2)) for j, c in enumerate(channels)}
    return {"chi2": chi2, "dof": dof, "chi2_per_dof": chi2 / dof, "p_value": float(stats.chi2.sf(chi2, dof)),
            "rms": rms, "chi2_per_point": chi2_ch, "n_failed": int(np.count_nonzero(~ok))}


def find(measured, model, sigma, conditions: dict, channels, rotor_radius: float) -> dict:
    """Where the nominal model disagrees: whitened residuals and their trends.

    Returns
    -------
    dict
        ``whitened`` (n_points, n_channels) list, per channel the χ²/point and the correlation
        of its whitened residual with tip-speed ratio, pitch, wind speed and load level, and the
        worst points.
    """
    w = (measured - model) / sigma
    lam = conditions["rotor_speed"] * np.pi / 30.0 * rotor_radius / conditions["wind_speed"]
    drivers = {"tip_speed_ratio": lam, "pitch": conditions["pitch"], "wind_speed": conditions["wind_speed"]}
    trends = {}
    for j, c in enumerate(channels):
        ok = np.isfinite(w[:, j])
        row = {"chi2_per_point": float(np.mean(w[ok, j] ** 2)), "mean_whitened": float(np.mean(w[ok, j]))}
        for name, x in {**drivers, "load_level": measured[:, j]}.items():
            xs = x[ok]
            row[f"corr_{name}"] = float(np.corrcoef(xs, w[ok, j])[0, 1]) if np.ptp(xs) > 0 and np.ptp(w[ok, j]) > 0 \
                else 0.0
        trends[c] = row
    order = np.argsort(-np.abs(np.nan_to_num(w)), axis=None)[:5]
    worst = [{"point": int(k // w.shape[1]), "channel": channels[int(k % w.shape[1])],
              "whitened_residual": float(w.flat[k])} for k in order]
    return {"trends": trends, "worst": worst, "tip_speed_ratio": lam.tolist()}


# ----------------------------------------------------------------------------- candidate fits
#: An own parameter of a candidate that ends within this fraction of its scale of its start
#: never left it: the fit is started again away from it (:func:`away_start`).
STUCK_TOLERANCE = 1e-6


def away_start(p: np.ndarray, lower: np.ndarray, upper: np.ndarray, scale: np.ndarray, which) -> np.ndarray:
    """A start one scale away from ``p`` in the parameters ``which``, toward the side with more room.

    Parameters
    ----------
    p, lower, upper, scale : ndarray
        The point a fit ended on, the bounds and the parameters' scales [parameter units].
    which : sequence of int
        The parameters to move (those that never left their start).

    Returns
    -------
    ndarray
        ``p`` with each of ``which`` moved by one scale (at most half the room to the bound it
        moves toward) into the interior: a candidate at zero magnitude, where the derivative
        of a shape parameter (an onset span, a radial exponent) vanishes and Gauss-Newton
        cannot take a step, starts where every parameter acts.
    """
    start = np.array(p, float)
    for j in which:
        up, down = upper[j] - p[j], p[j] - lower[j]
        room = up if up >= down else -down
        start[j] = p[j] + np.sign(room) * min(abs(scale[j]), 0.5 * abs(room))
    return start


def _fit_task(task: dict) -> dict:
    """Fit one candidate (module-level so executors can ship it to other processes).

    A candidate's own parameter (``task["own"]``: its indices) that ends where it started, to
    :data:`STUCK_TOLERANCE` of its scale, may sit on a stationary point of χ² (every derivative
    of a zero-magnitude effect's shape parameters vanishes at nominal): the fit is started
    again from :func:`away_start` and the one with the lower χ² is kept; the fit's status says
    which ("second start kept" / "second start not kept").
    """
    model = task["model"]
    meas = task["measurements"]
    st = dataclasses.replace(task["settings"], prior_check=False, tightening=False)   # a comparison: no advice
    names = [c.name for c in model.channels]
    cols = [names.index(c) for c in meas.channels]

    def fit(start=None):
        res = Calibrator(model, meas, st, name=task["name"], start=start).run()
        values = model.evaluate(res.p_hat, meas.conditions).values[:, cols]
        ok = np.isfinite(values).all(axis=1)
        chi2 = float(np.sum(((meas.values - values) / meas.sigma)[ok] ** 2)) if ok.any() else float("inf")
        return res, values, chi2

    try:
        res, values, chi2 = fit()
    except CalibError as exc:        # this candidate failed; the others are still compared
        return {"error": f"{type(exc).__name__}: {exc}"}
    own = list(task.get("own", range(res.n_params)))
    stuck = [j for j in own if abs(res.p_hat[j] - res.p_nominal[j]) <= STUCK_TOLERANCE * res.scale[j]]
    note = ""
    if stuck:
        try:
            res2, values2, chi2_2 = fit(away_start(res.p_hat, res.lower, res.upper, res.scale, stuck))
        except CalibError as exc:
            note = f"second start failed ({type(exc).__name__})"
        else:
            keep = chi2_2 < chi2
            note = f"second start {'kept' if keep else 'not kept'} (χ² {chi2_2:.6g} against {chi2:.6g})"
            if keep:
                res, values = res2, values2
    return {"result": res, "values": values, "start_note": note}


def _variants(name: str, options: dict) -> list:
    """(label, effect) for every variant of effect ``name`` (one entry when it has none or the
    options fix it): the model forms of one physical effect compete among themselves, and the
    best one names the effect."""
    cls = EFFECTS[name]
    choices = getattr(cls, "CHOICES", {}).get("variant")
    if not choices or "variant" in options:
        return [(name, make_effect(name, **options))]
    return [(f"{name}:{v}", make_effect(name, **{**options, "variant": v})) for v in choices]


def _candidate_model(rotor, channels, settings, base_effects, effect):
    return BemModel(rotor, None, channels, settings, (), effects=list(base_effects) + [effect])


def bound_side(value: float, lower: float, upper: float, scale: float,
               tolerance: float = AT_BOUND_TOLERANCE) -> str:
    """Which bound a fitted value sits on: ``"lower"``, ``"upper"`` or ``""`` (neither).

    Parameters
    ----------
    value, lower, upper : float
        The estimate and the parameter's bounds [parameter unit].
    scale : float
        The parameter's scale, a typical meaningful change [parameter unit].
    tolerance : float
        A value within ``tolerance`` × ``scale`` of a bound, or past it (round-off of the
        optimizer's step ends an estimate a few ulp outside), is at that bound [-]. The
        default, 10⁻³ of the scale, is far below any σ a fit gives.
    """
    tol = tolerance * abs(float(scale))
    if value <= lower + tol:
        return "lower"
    if value >= upper - tol:
        return "upper"
    return ""


def _fixed_effect(effect_spec: dict, fitted: dict):
    """The effect of ``effect_spec`` with its fitted values as nominal (frozen in later rounds).

    A fitted value is clipped into its parameter's bounds first: an estimate that ends on a
    bound may lie a few ulp past it, which is the bound, not an invalid nominal value.
    """
    options = dict(effect_spec.get("options", {}))
    bare = make_effect(effect_spec["name"], **{k: v for k, v in options.items() if k != "nominal"})
    bounds = {q.name: (q.lower, q.upper) for q in bare.parameters()}
    clipped = {k: float(np.clip(v, *bounds[k])) if k in bounds else v for k, v in fitted.items()}
    options["nominal"] = {**options.get("nominal", {}), **clipped}
    return make_effect(effect_spec["name"], **options)


def _tagged(callback, run: str):
    """``callback`` receiving Calibrator records with ``run`` added (None stays None)."""
    return None if callback is None else (lambda rec: callback({"run": run, **rec}))


class BemFamily:
    """The models a diagnosis on the native BEM calibrates: candidates are the effects of
    :data:`calib.effects.EFFECTS` switched into a :class:`~calib.models.bem_model.BemModel`.

    Every family offers the same few calls, so :func:`diagnose` runs unchanged on another
    kind of model (:class:`calib.diagnosis.fmu.FmuFamily`).
    """

    def __init__(self, rotor, channels, grid, settings, rotor_source=None):
        self.rotor, self.channels, self.grid, self.settings = rotor, list(channels), grid, settings
        self.rotor_source = rotor_source
        self.rotor_radius = rotor.rotor_radius
        self.names = NAMEABLE

    def field_model(self, base=()):
        """The correction field on top of the fixed ``base`` effects (localize, recalibrate)."""
        return BemModel(self.rotor, self.grid, self.channels, self.settings, (), effects=list(base),
                        rotor_source=self.rotor_source)

    def nominal_model(self):
        return BemModel(self.rotor, None, self.channels, self.settings, (), rotor_source=self.rotor_source)

    def variants(self, name: str, options: dict) -> list:
        return _variants(name, options)

    def candidate_model(self, base, effect):
        return _candidate_model(self.rotor, self.channels, self.settings, base, effect)

    def check(self, base, effect, conditions) -> None:
        """Raise InputError when ``effect`` cannot act on this rotor (reported not applicable)."""
        model = self.candidate_model(base, effect)
        model.evaluate(np.array([q.nominal for q in model.parameters]), conditions.subset(slice(0, 1)))

    def n_parameters(self, base) -> int:
        return sum(len(e.parameters()) for e in base)

    def spec(self, effect) -> dict:
        return effect.spec()

    def add(self, base, best: "CandidateFit") -> list:
        """``base`` with the named candidate added at its fitted values."""
        return list(base) + [_fixed_effect(best.spec, {q["name"]: q["value"] for q in best.parameters})]

    def names_of(self, base) -> list:
        return [e.name for e in base]

    def probe_channels(self, measured: list) -> list:
        """Channels the separation probes predict: the measured ones, the rotor loads and the
        normal force per length at four spanwise stations (:mod:`calib.diagnosis.separation`)."""
        extra = ["power", "thrust", "root_flap_moment"] + [f"fn@{eta:.2f}" for eta in PROBE_STATIONS]
        return list(measured) + [c for c in extra if c not in measured]

    def predict(self, base, effect, p: np.ndarray, conditions, channels: list) -> tuple[np.ndarray, list]:
        """A fitted candidate's outputs and their units at ``conditions``."""
        model = BemModel(self.rotor, None, channels, self.settings, (), effects=list(base) + [effect],
                         rotor_source=self.rotor_source)
        ev = model.evaluate(p, conditions)
        return ev.values, [c.unit for c in model.channels]

    def fingerprint(self, name: str) -> str:
        return getattr(EFFECTS.get(name), "fingerprint", "")


#: Spanwise stations r/R of the normal-force probes (:meth:`BemFamily.probe_channels`).
PROBE_STATIONS = (0.3, 0.5, 0.7, 0.9)


def diagnose(rotor, measurements: Measurements, grid: CorrectionGrid, settings: BemSettings | None = None,
             calibration: CalibrationSettings | None = None, diagnosis: DiagnosisSettings | None = None,
             executor=None, progress: Callable[[str], None] | None = None, rotor_source: dict | None = None,
             wrap: Callable | None = None, fit_progress: Callable[[int, int], None] | None = None,
             family=None, on_iteration: Callable[[dict], None] | None = None) -> Diagnosis:
    """Run the discrepancy workflow on the native BEM (see the module notes).

    Parameters
    ----------
    rotor : Rotor
    measurements : Measurements
        Channels of the native BEM; σ from ``_sigma`` columns, ``calibration.sigma``, or
        estimated (``calibration.noise = "ml"``) by the localization step.
    grid : CorrectionGrid
        Nodes of the correction field (localization and recalibration).
    settings : BemSettings, optional
    calibration : CalibrationSettings, optional
        For the localization and the recalibration (the candidate fits retain every parameter).
    diagnosis : DiagnosisSettings, optional
    executor : Executor, optional
        Runs the candidate fits (:mod:`calib.executors`; default serial).
    progress : callable(str), optional
        Receives one line per step.
    wrap : callable(model, label) -> model, optional
        Applied to every model the diagnosis calibrates or evaluates (e.g.
        :func:`calib.history.recorded`, which records each call and answers it on resume).
    fit_progress : callable(done, total), optional
        Called as the candidate fits of a round finish.
    family : optional
        The models to calibrate (default :class:`BemFamily` of ``rotor``, ``grid``,
        ``settings``); e.g. :class:`calib.diagnosis.fmu.FmuFamily` for an FMU.
    on_iteration : callable(dict), optional
        Receives every optimizer iteration record of the localization and the recalibration
        (:class:`~calib.calibration.Calibrator` records with ``run`` added).

    Returns
    -------
    Diagnosis
        With ``failure`` non-empty when a naming round or the recalibration failed: the
        rounds before it, and the gap with the effects they named, are still reported.
    """
    t0 = time.perf_counter()
    settings = settings or BemSettings()
    channels = list(measurements.channels)
    family = family or BemFamily(rotor, channels, grid, settings, rotor_source)
    # the diagnosis's fits (localization, candidates, recalibration) use the truncated estimator:
    # its statistics (Λ, ΔBIC, pattern agreement, the gates) were set and validated with it, in and
    # out of family; the MAP estimator is not yet measured there
    cal = dataclasses.replace(calibration or CalibrationSettings(), estimator="truncated").validate()
    dset = (diagnosis or DiagnosisSettings()).validate(valid=family.names)
    say = progress or (lambda s: None)
    candidates = tuple(dset.candidates) if dset.candidates is not None else tuple(family.names)
    if executor is None:
        from calib.executors import SerialExecutor
        executor = SerialExecutor()
    wrap = wrap or (lambda model, label: model)

    # 2. localize (first: with noise = "ml" it gives the σ every later step uses)
    field_model = wrap(family.field_model(), "localization")
    say(f"localize: correction field, {len(field_model.parameters)} parameters")
    loc = Calibrator(field_model, measurements, cal, _tagged(on_iteration, "localization"), name="localization").run()
    sigma = loc.sigma
    meas = dataclasses.replace(measurements, sigma=sigma)
    known = dataclasses.replace(cal, noise="known", sigma=None, retain="all")
    say(f"localize: {loc.n_retained} of {loc.n_params} θ retained, χ²/dof {loc.chi2_per_dof_after:.3g}")

    # 1. find
    base_model = wrap(family.nominal_model(), "nominal")
    y0 = base_model.evaluate(np.zeros(0), meas.conditions).values
    before = gap(meas.values, y0, sigma, channels)
    findings = find(meas.values, y0, sigma, meas.conditions.as_dict(), channels, family.rotor_radius)
    say(f"find: nominal χ²/dof {before['chi2_per_dof']:.3g} ({p_is(before['p_value'])})")

    # 3. name, up to max_effects rounds (a round that fails ends the naming; earlier rounds stand),
    # against the noise plus the model-form tolerance
    tol = dset.tolerance_of(channels)
    meas_name = dataclasses.replace(meas, sigma=np.hypot(sigma, tol * np.abs(np.nan_to_num(y0))))
    before_name = gap(meas.values, y0, meas_name.sigma, channels)
    namer = _Namer(family, meas_name, y0, before_name["chi2"], (loc.model_after - y0) / meas_name.sigma, dset,
                   known, executor, wrap, fit_progress, say, tol)
    # the global test gates everything, where the noise is stated: an estimated σ is fitted to the
    # localization's residuals, so the nominal model would pass against it by construction
    if cal.noise not in ESTIMATED_NOISE and before_name["p_value"] >= dset.significance:
        namer.consistent(before_name, within_tolerance=before["p_value"] < dset.significance)
    else:
        namer.run(candidates)
    effect, effects_named = namer.verdict()
    n_fit = family.n_parameters(namer.base_effects)
    with_effects = gap(meas.values, namer.base_values, sigma, channels, n_fit)

    # 4. add + recalibrate the field on top
    recal = _recalibrate(family, namer, meas, cal, dset, wrap, on_iteration, say, effects_named)
    y_after = None if recal is None else recal.model_after
    after = with_effects if recal is None else gap(meas.values, y_after, sigma, channels, n_fit + recal.n_retained)
    say(f"show: χ²/dof {before['chi2_per_dof']:.3g} -> {with_effects['chi2_per_dof']:.3g} with "
        f"{', '.join(effects_named) or 'no effect'}" + ("" if recal is None else
                                                        f" -> {after['chi2_per_dof']:.3g} after recalibration"))
    return Diagnosis(effect, effects_named, namer.rounds, before, with_effects, after, findings, loc, recal, channels,
                     meas.values, sigma, meas.conditions.as_dict(), y0, namer.base_values, y_after,
                     family.rotor_radius, time.perf_counter() - t0, namer.notes, "; ".join(namer.failures))


def _recalibrate(family, namer: "_Namer", meas, cal, dset, wrap, on_iteration, say, effects_named):
    """The correction field recalibrated on top of the named effects (a CalibrationResult), or
    None when switched off or when it fails (the failure is noted)."""
    if not dset.recalibrate:
        return None
    model = wrap(family.field_model(namer.base_effects), "recalibration")
    known_field = dataclasses.replace(cal, noise="known", sigma=None)
    say("recalibrate: correction field on top of " + (", ".join(effects_named) or "the nominal model"))
    try:
        recal = Calibrator(model, meas, known_field, _tagged(on_iteration, "recalibration"),
                           name="recalibration").run()
    except CalibError as exc:
        namer.fail(f"the recalibration failed: {exc}; the figures after it are those with the named effect(s)")
        return None
    chi2 = gap(meas.values, recal.model_after, meas.sigma, list(meas.channels))["chi2"]
    start = gap(meas.values, namer.base_values, meas.sigma, list(meas.channels))["chi2"]
    if not chi2 <= start * (1 + RECALIBRATION_SLACK):
        # the nominal field is inside the search space: a larger χ² is an optimizer that ended
        # worse than where it started, never a better model
        namer.notes.append(f"the recalibration ended with χ² {chi2:.6g} above the {start:.6g} of the model "
                           f"with {', '.join(effects_named) or 'no effect'} ({recal.status}); it is not kept")
        say(f"recalibrate: {namer.notes[-1]}")
        return None
    return recal


class _Namer:
    """Step 3 of :func:`diagnose`: naming rounds, each on top of the effects named before.

    A round that raises a :class:`~calib.errors.CalibError` (a fit that cannot run, an effect
    that cannot take its fitted values) is recorded with verdict ``failed`` and the failure in
    words; the naming stops there and what the earlier rounds found stands.
    """

    def __init__(self, family, meas, y0, chi2_nominal, field_change, dset, known, executor, wrap, fit_progress,
                 say, tolerance=None):
        self.family, self.meas, self.y0, self.field_change = family, meas, y0, field_change
        self.dset, self.known, self.executor, self.wrap = dset, known, executor, wrap
        self.fit_progress, self.say = fit_progress, say
        self.base_effects, self.named, self.rounds, self.notes, self.failures = [], [], [], [], []
        self.base_chi2, self.base_values = chi2_nominal, y0
        self.n_res = int(np.isfinite(y0).all(axis=1).sum() * y0.shape[1])
        self.remaining, self._fits = [], []       # _fits: the current round's fits (kept if it fails)
        self._effects = {}                        # the current round's candidate effects by label
        self.tolerance = np.zeros(y0.shape[1]) if tolerance is None else np.asarray(tolerance, float)

    def run(self, candidates) -> None:
        self.remaining = list(candidates)
        for round_no in range(self.dset.max_effects):
            if not self.remaining:
                break
            self._fits = []
            try:
                if self._round(round_no):
                    break
            except CalibError as exc:
                self.rounds.append({"base": self.family.names_of(self.base_effects), "candidates": self._fits,
                                    "verdict": "failed", "reason": f"failed: {exc}"})
                before = {0: "no effect was named", 1: "what round 1 found stands"}.get(
                    round_no, f"what rounds 1-{round_no} found stands")
                self.fail(f"naming round {round_no + 1} failed: {exc}; {before}")
                break

    def consistent(self, before: dict, within_tolerance: bool = False) -> None:
        """The nominal model passes the global χ² test (noise plus model-form tolerance): nothing
        is named (a likelihood ratio that is significant on top of a model that already fits is
        code-to-code residue, not an effect the data demand)."""
        what = ("within the model-form tolerance (it misses the noise alone, but not the noise plus the "
                "tolerance)" if within_tolerance else "consistent with the noise")
        reason = (f"the nominal model is {what} (χ²/dof {before['chi2_per_dof']:.3g} over {before['dof']} "
                  f"residuals, {p_is(before['p_value'])} ≥ significance {self.dset.significance:g}): no effect is "
                  "looked for")
        self.rounds.append({"base": [], "candidates": [], "verdict": "none", "reason": reason})
        self.say(f"name: {reason}")

    def fail(self, message: str) -> None:
        self.failures.append(message)
        self.notes.append(message)
        self.say(message)

    def verdict(self) -> tuple[str, list]:
        """The diagnosis' one-word result and the effects named (in order)."""
        effects_named = [n for n in self.named if not n.startswith("ambiguous:")]
        if self.named and self.named[0].startswith("ambiguous:"):
            return "ambiguous", effects_named
        return (effects_named[0] if effects_named else "none"), effects_named

    def _round(self, round_no: int) -> bool:
        """One naming round; True when the naming is over."""
        labels, effects = self._applicable()
        if not labels:
            return True
        self._effects = effects
        self._fits = fits = self._fit(round_no, labels, effects)
        rnd, best = self._judge(fits)
        if best is None:
            self.rounds.append(rnd)
            if rnd["verdict"] == "ambiguous" and not self.named:
                self.named.append("ambiguous:" + "+".join(rnd["ambiguous"]))
            return True
        new_base = self.family.add(self.base_effects, best)    # may raise: the round then fails
        self.rounds.append(rnd)
        self.named.append(best.effect)
        self.base_effects = new_base
        self.base_chi2, self.base_values = best.chi2, best.model_values
        self.remaining = [c for c in self.remaining if c != best.effect]
        # a further effect is looked for only while the model is still inconsistent with the noise
        fit_now = gap(self.meas.values, self.base_values, self.meas.sigma, list(self.meas.channels),
                      self.family.n_parameters(self.base_effects))
        if fit_now["p_value"] >= self.dset.significance:
            self.say(f"name: with {', '.join(self.named)} the model is consistent with the noise (χ²/dof "
                     f"{fit_now['chi2_per_dof']:.3g}, {p_is(fit_now['p_value'])}); no further effect is looked for")
            return True
        return False

    def _applicable(self) -> tuple[list, dict]:
        """Labels and effects of the remaining candidates' variants that can act on this rotor."""
        labels, effects = [], {}
        for c in list(self.remaining):
            try:
                variants = self.family.variants(c, self.dset.candidate_options.get(c, {}))
                for label, effect in variants:
                    # an effect that cannot act on this rotor (e.g. no reference Reynolds number) is
                    # reported as not applicable, not fitted
                    self.family.check(self.base_effects, effect, self.meas.conditions)
            except InputError as exc:
                self.notes.append(f"candidate {c} not applicable: {exc}")
                self.say(f"name: candidate {c} not applicable: {exc}")
                self.remaining.remove(c)
                continue
            for label, effect in variants:
                labels.append(label)
                effects[label] = effect
        return labels, effects

    def _fit(self, round_no: int, labels: list, effects: dict) -> list:
        """Every candidate fitted on top of the base effects, scored against the base model."""
        n_base = self.family.n_parameters(self.base_effects)
        tasks = [{"name": lab, "measurements": self.meas, "settings": self.known,
                  "own": list(range(n_base, n_base + len(effects[lab].parameters()))),
                  "model": self.wrap(self.family.candidate_model(self.base_effects, effects[lab]),
                                     f"round {round_no + 1}: {lab}")} for lab in labels]
        self.say(f"name (round {round_no + 1}): fitting {len(tasks)} candidates")
        outs = self.executor.map(_fit_task, tasks, self.fit_progress)
        alpha = self.dset.significance / max(len(self.remaining), 1)
        failed = [(lab, out["error"]) for lab, out in zip(labels, outs) if "error" in out]
        for lab, message in failed:
            self.notes.append(f"round {round_no + 1}: the fit of candidate {lab} failed and it is left out of the "
                              f"comparison: {message}")
            self.say(f"name: {self.notes[-1]}")
        if len(failed) == len(labels):
            raise CalibError(f"every candidate fit of round {round_no + 1} failed (first: {failed[0][1]})")
        return [self._score(lab, out, effects[lab], alpha) for lab, out in zip(labels, outs) if "error" not in out]

    def _score(self, label: str, out: dict, effect, alpha: float) -> CandidateFit:
        res, values = out["result"], out["values"]
        meas, sigma = self.meas, self.meas.sigma
        own = list(range(self.family.n_parameters(self.base_effects), res.n_params))
        chi2 = float(np.sum(((meas.values - values) / sigma)[np.isfinite(values).all(axis=1)] ** 2))
        k = len(own)
        lr = max(self.base_chi2 - chi2, 0.0)
        p = float(stats.chi2.sf(lr, k)) if k else 1.0
        change = (values - self.base_values) / sigma
        a, b = change.reshape(-1), (self.field_change - (self.base_values - self.y0) / sigma).reshape(-1)
        good = np.isfinite(a) & np.isfinite(b)
        agree = float(np.corrcoef(a[good], b[good])[0, 1]) if good.sum() > 2 and np.std(a[good]) > 0 and \
            np.std(b[good]) > 0 else float("nan")
        params = _parameter_records(res, own)
        size, words, exceeds = effect_size(values, self.base_values, self.tolerance, list(meas.channels),
                                           meas.conditions.wind_speed)
        return CandidateFit(label, params, chi2, k, -0.5 * chi2, chi2 + k * np.log(self.n_res), lr, p,
                            p < alpha and exceeds, pattern_agreement=agree, status=res.status,
                            start=out.get("start_note", ""), p_hat=np.array(res.p_hat, float),
                            spec=self.family.spec(effect), model_values=values, effect=label.split(":")[0],
                            at_bound=[q["name"] for q in params if q["at_bound"]], effect_size=size,
                            effect_text=words)

    def _judge(self, fits: list) -> tuple[dict, CandidateFit | None]:
        """The round's record (BIC weights set, candidates sorted by BIC) and the candidate it
        names (None for ``none`` and ``ambiguous``)."""
        dset = self.dset
        bics = np.array([f.bic for f in fits] + [self.base_chi2])
        wts = np.exp(-0.5 * (bics - bics.min()))
        wts /= wts.sum()
        for f, wgt in zip(fits, wts[:-1]):
            f.weight = float(wgt)
        fits.sort(key=lambda f: f.bic)
        rnd = {"base": self.family.names_of(self.base_effects), "candidates": fits}
        sig = [f for f in fits if f.significant]
        if not sig:
            small = [f for f in fits if f.p_value < dset.significance / max(len(fits), 1) and not f.significant]
            tail = (f"; {small[0].name} would be significant by likelihood ratio, but its change of the outputs "
                    f"({small[0].effect_text}) is within the model-form tolerance" if small else "")
            rnd.update(verdict="none", reason=(
                f"no candidate improves the fit significantly (likelihood ratio at family-wise level "
                f"{dset.significance:g}); best {fits[0].name}: Λ = {fits[0].lr_statistic:.3g}, "
                f"{p_is(fits[0].p_value)}" + _bound_suffix(fits[0]) + tail))
            self.say(f"name: {rnd['reason']}")
            return rnd, None
        best = sig[0]
        # variants of the same effect are not rivals: the best variant names the effect
        rivals = [f for f in sig[1:] if f.bic - best.bic < dset.ambiguity_bic and f.effect != best.effect]
        pattern_note = ""
        if rivals:
            rival = rivals[0]
            a, b = best.pattern_agreement, rival.pattern_agreement
            close = f"{best.effect} and {rival.effect} fit about equally well (ΔBIC = {rival.bic - best.bic:.3g} < " \
                    f"{dset.ambiguity_bic:g})"
            if np.isfinite(a) and np.isfinite(b) and abs(a - b) >= dset.ambiguity_pattern:
                # the information criterion cannot tell them apart, the pattern can
                best, other = (best, rival) if a > b else (rival, best)
                pattern_note = (f"; {close}, but the pattern of {best.effect} agrees better with the localized "
                                f"correction ({best.pattern_agreement:.2f} against {other.pattern_agreement:.2f}, "
                                f"a difference of at least {dset.ambiguity_pattern:g})")
            else:
                separate = _separation_of(self, best, rival)
                rnd.update(verdict="ambiguous", ambiguous=[best.effect, rival.effect], separate=separate, reason=(
                    f"{close} and their patterns agree equally with the localized correction ({a:.2f} and {b:.2f}): "
                    f"the data cannot tell them apart; {separate['text']}"))
                self.say(f"name: {rnd['reason']}")
                return rnd, None
        nxt = fits[1] if len(fits) > 1 else None
        rnd.update(verdict=best.effect, reason=(
            f"{best.name}: Λ = {best.lr_statistic:.4g} for {best.n_params} parameter(s), {p_is(best.p_value)}; "
            f"BIC weight {best.weight:.3f}; next {nxt.name if nxt else 'none'} ΔBIC = "
            f"{(nxt.bic - best.bic) if nxt else float('inf'):.3g}; pattern agreement with the localized correction "
            f"{best.pattern_agreement:.2f}; effect {best.effect_text}" + _bound_suffix(best) + pattern_note))
        self.say(f"name: {rnd['reason']}")
        return rnd, best


def _separation_of(namer: "_Namer", a: CandidateFit, b: CandidateFit) -> dict:
    """The measurement that would tell ``a`` from ``b`` (:mod:`calib.diagnosis.separation`): {"text", "probes",
    "envelope", "fingerprints"}; a probe that cannot be evaluated is said, never raised."""
    fam, meas = namer.family, namer.meas
    names = (a.effect, b.effect)
    fingerprints = {n: fam.fingerprint(n) for n in names if fam.fingerprint(n)}
    envelope = envelope_words(meas.conditions, fam.rotor_radius)
    out = {"probes": [], "envelope": envelope, "fingerprints": fingerprints}
    try:
        probes = probe_conditions(meas.conditions, fam.rotor_radius)
        both = OperatingConditions(*(np.concatenate([getattr(meas.conditions, f), getattr(probes, f)])
                                     for f in CONDITION_FIELDS))
        channels = fam.probe_channels(list(meas.channels))
        va, units = fam.predict(namer.base_effects, namer._effects[a.name], a.p_hat, both, channels)
        vb, _ = fam.predict(namer.base_effects, namer._effects[b.name], b.p_hat, both, channels)
    except CalibError as exc:
        out["text"] = f"the probes that would separate them could not be evaluated ({exc})"
        return out
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = {c: float(np.nanmedian(np.where(namer.y0[:, j] != 0, meas.sigma[:, j] / np.abs(namer.y0[:, j]), np.nan)))
               for j, c in enumerate(meas.channels)}
    rel = {c: r for c, r in rel.items() if np.isfinite(r) and r > 0}
    found = separating_probes(va, vb, both, channels, list(meas.channels), rel, len(meas.conditions),
                              fam.rotor_radius)
    unit = dict(zip(channels, units))
    out["probes"] = [{**dataclasses.asdict(p), "words": p.words(names, unit[p.channel])} for p in found]
    if not found:
        text = "no probe could compare them"
    elif found[0].separation > 1.0:
        text = "to tell them apart, measure " + "; or ".join(p["words"] for p in out["probes"] if p["separation"] > 1)
    else:
        text = ("no probe considered separates them beyond the noise and model-form tolerance (closest: "
                f"{out['probes'][0]['words']})")
    text += f"; the campaign measured {envelope}"
    if fingerprints:
        text += "; fingerprints: " + "; ".join(f"{n}: {fp}" for n, fp in fingerprints.items())
    out["text"] = text
    return out


def _bound_suffix(fit: CandidateFit) -> str:
    """"; <fit's parameters at a bound>, ..." for a verdict ("" when none is at a bound)."""
    phrase = fit.bound_phrase()
    return (f"; {phrase}: the fit pushed against the bound, so the value is the bound, not an estimate (the "
            f"effect may stand in for another one, or the data hold a gross error)") if phrase else ""


def _parameter_records(res, own: list) -> list[dict]:
    """{name, value, std, unit, nominal, lower, upper, at_bound} of a candidate's own parameters."""
    out = []
    for j in own:
        lo, hi = float(res.lower[j]), float(res.upper[j])
        value = float(res.p_hat[j])
        out.append({"name": res.parameters[j]["name"], "value": value, "std": float(res.std_p[j]),
                    "unit": res.parameters[j]["unit"], "nominal": float(res.p_nominal[j]), "lower": lo, "upper": hi,
                    "at_bound": bound_side(value, lo, hi, float(res.scale[j]))})
    return out
