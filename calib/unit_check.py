"""Unit mistakes caught before calibrating: the measurements against the nominal model.

A table whose power is in kW under a ``[W]`` header, or whose wind speed is in km/h under
``[m/s]``, calibrates to a confident nonsense (a σ of 10¹⁰ W, a pitch offset at its bound).
:func:`check_units` compares the data with the nominal model at the measured operating
points and names the channel or the condition that looks wrong, and by which factor:

1. Evaluate the model at the conditions as read (hypothesis "as read") and, for each
   condition in ``conditions`` and each of its unit factors (:data:`CONDITION_FACTORS`), at
   the conditions corrected by that factor (a few model evaluations in all).
2. Under each hypothesis, per channel, the robust ratio ρ_c = median_k (z_kc / y_kc) over the
   points where the model value is at least 10 % of the channel's largest; if ρ_c is within
   ``factor_tolerance`` of a unit factor f ≠ 1 (:data:`CHANNEL_FACTORS`, either sign) and at
   least half of the points agree, the channel is taken to be off by f and divided by it.
3. The misfit of a hypothesis is the mean of χ² over all values,

   χ²_kc = (z_kc / f_c − y_kc)² / (σ_kc² + (ε y_kc)² + (10⁻³ ỹ_c)²),

   with σ the table's (or the settings') noise, or ``relative_sigma`` × |y| when unknown;
   ε = ``model_error`` an allowance for the uncalibrated model (a polar error of 10 % is what
   calibration is for, not a reason to stop), and ỹ_c the channel's RMS model value (a floor
   for points where the model is near zero). A point where the model fails counts
   ``chi2_threshold`` per channel.
4. A condition hypothesis explains the data when the misfit as read exceeds 1, and the
   hypothesis brings it to at most ``chi2_threshold`` and at least ten times lower.

Findings. Those a unit factor (or a sign) explains stop the run through
:meth:`UnitCheckReport.raise_if_failed` unless forced:

- ``condition``: a condition off by a unit factor (wind speed ×3.6: km/h read as m/s);
- ``channel``: a channel off by a unit factor (power ×10⁻³: kW read as W);
- ``sign``: a channel with the opposite sign of the model's (measured/model ≈ −1);
- ``gross``: a channel misfit whose ratio lies outside 1/5 to 5 (:data:`GROSS_RATIO`) without
  matching a unit factor (a kW table whose loads are also off): no polar correction explains it.

Those no unit factor explains are warnings: a misfit is what calibration is for, so the run
goes on and says so loudly (stopped only with ``strict``):

- ``misfit``: a channel whose χ²/dof, after any correction above, still exceeds
  ``chi2_threshold`` (no unit factor explains it);
- ``failures``: the model fails at more than half of the measured points.

Factors are stated as *read / meant*: a factor 3.6 on the wind speed means the numbers
read are 3.6 times the values that make the model match (km/h under an m/s header).

Limits: a condition that is zero everywhere (pitch at fine pitch) cannot show a unit
mistake and is said so in a note; two condition mistakes at once are not searched (the
misfit finding still stops the run); yaw and air density are not checked.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from calib.errors import CalibError, InputError
from calib.measurements import UNITS, Measurements, check_channels, quantity_of, si_unit
from calib.types import CONDITION_FIELDS, OperatingConditions

_RPM = 30.0 / np.pi       # rpm per rad/s
_DEG = 180.0 / np.pi      # deg per rad

#: Unit factors a channel may be off by (read / meant), without sign.
CHANNEL_FACTORS = (1e3, 1e-3, 1e6, 1e-6, 3.6, 1 / 3.6, _RPM, 1 / _RPM, _DEG, 1 / _DEG)

#: Unit factors (read / meant) tried per condition.
CONDITION_FACTORS = {
    "wind_speed": (3.6, 1 / 3.6),        # km/h read as m/s, m/s read as km/h
    "rotor_speed": (1 / _RPM, _RPM),     # rad/s read as rpm, rpm read as rad/s
    "pitch": (1 / _DEG, _DEG),           # rad read as deg, deg read as rad
}

#: How to override a stopped run (wired by the command line and the workflow).
OVERRIDE_HINT = "to go on anyway, pass --force (workflow or diagnose config: [calibration] force = true)"

#: Finding kinds that stop the run unless forced: a unit factor or a sign explains them, or the
#: ratio is beyond anything a polar correction gives (``gross``).
STOPPING_KINDS = ("condition", "channel", "sign", "gross")

#: A channel whose measured/model ratio lies outside [1/GROSS_RATIO, GROSS_RATIO] is not a model
#: misfit: no calibration of the polars moves a rotor load by a factor of 5 [-].
GROSS_RATIO = 5.0

_FACTOR_WORDS = ((1e3, "10³", "10⁻³", "a k prefix"), (1e6, "10⁶", "10⁻⁶", "an M prefix"),
                 (3.6, "3.6", "1/3.6", "km/h ↔ m/s"), (_RPM, "30/π", "π/30", "rpm ↔ rad/s"),
                 (_DEG, "180/π", "π/180", "deg ↔ rad"))
_CONDITION_SI = {"wind_speed": "speed", "rotor_speed": "rotor_speed", "pitch": "angle"}
_EXPLAIN_GAIN = 10.0       # a hypothesis must lower the misfit this many times to explain the data
_USABLE = 0.1              # ratios from points with |model| >= this x the channel's largest |model|
_FLOOR = 1e-3              # σ floor as a fraction of the channel's RMS model value


@dataclass(frozen=True)
class UnitFinding:
    """One reason to stop before calibrating.

    Attributes
    ----------
    kind : str
        ``"condition"``, ``"channel"``, ``"sign"``, ``"misfit"`` or ``"failures"``.
    name : str
        The condition or channel (``""`` for ``failures``).
    factor : float
        Suspected factor, read / meant [-] (NaN for ``misfit`` and ``failures``).
    message : str
        The probable mistake in words, with the numbers behind it.
    """

    kind: str
    name: str
    factor: float
    message: str

    def as_dict(self) -> dict:
        return {"kind": self.kind, "name": self.name,
                "factor": None if np.isnan(self.factor) else float(self.factor), "message": self.message}


@dataclass(frozen=True)
class UnitCheckReport:
    """Outcome of :func:`check_units`.

    Attributes
    ----------
    findings : tuple of UnitFinding
        Empty when the data look consistent with the model's units.
    ratios : dict channel -> float
        Median measured/model per channel, as read [-].
    chi2_per_dof : dict channel -> float
        χ²/dof per channel as read, with the σ of the module docstring [-].
    chi2_threshold : float
    hypotheses : tuple of (str, float)
        Each hypothesis tried ("as read", "wind_speed x 3.6" ...) and its misfit [-].
    notes : tuple of str
        What the check could not see or assumed (σ unknown, a condition all zero ...).
    source : str
        Where the measurements came from.
    n_points, n_failed : int
        Measured points; points where the nominal model failed as read.
    """

    findings: tuple[UnitFinding, ...]
    ratios: dict
    chi2_per_dof: dict
    chi2_threshold: float
    hypotheses: tuple
    notes: tuple[str, ...]
    source: str
    n_points: int
    n_failed: int

    @property
    def ok(self) -> bool:
        """True when nothing suggests a unit mistake or a gross misfit."""
        return not self.findings

    @property
    def unit_findings(self) -> tuple[UnitFinding, ...]:
        """Findings a unit factor or a sign explains (:data:`STOPPING_KINDS`)."""
        return tuple(f for f in self.findings if f.kind in STOPPING_KINDS)

    @property
    def misfit_findings(self) -> tuple[UnitFinding, ...]:
        """Findings no unit factor explains (gross misfit, failures): warnings, not stops."""
        return tuple(f for f in self.findings if f.kind not in STOPPING_KINDS)

    def summary(self) -> str:
        """Lines a user reads: verdict, per-channel ratio and χ²/dof, findings, notes."""
        head = "unit check: " + ("passed" if self.ok else f"{len(self.findings)} finding(s)")
        per = ", ".join(f"{c} {self.ratios[c]:.3g} (χ²/dof {self.chi2_per_dof[c]:.3g})" for c in self.ratios)
        lines = [head, f"  measured/model as read: {per}"]
        lines += [f"  - {f.message}" for f in self.findings]
        lines += [f"  note: {n}" for n in self.notes]
        return "\n".join(lines)

    def raise_if_failed(self, source: str | None = None, strict: bool = False) -> None:
        """Raise :class:`~calib.errors.InputError` listing the findings a unit factor explains.

        Parameters
        ----------
        source : str, optional
            File named in the error (default: the measurements' source).
        strict : bool
            Also stop on the findings no unit factor explains (misfit, failures).
        """
        stop = self.findings if strict else self.unit_findings
        if not stop:
            return
        body = "; ".join(f.message for f in stop)
        what = "Fix the header or the data" if any(f.kind in STOPPING_KINDS for f in stop) else \
            "Strict unit check (--strict-units): no unit factor explains this misfit"
        raise InputError(f"unit check failed before calibrating: {body}. {what}; {OVERRIDE_HINT}",
                         source or self.source, field=stop[0].name or None)

    def warning_lines(self) -> list[str]:
        """The loud line for misfits no unit factor explains (empty when there are none)."""
        if not self.misfit_findings:
            return []
        names = ", ".join(f.name or "points failing" for f in self.misfit_findings)
        return [f"WARNING: the nominal model misses {names} beyond noise and model error, and no unit factor "
                f"explains it ({self.ratio_words()}); calibrating anyway, since such a misfit is what calibration "
                f"is for (--strict-units stops here instead)"]

    def ratio_words(self) -> str:
        """'measured/model per channel: power 0.521 (χ²/dof 33.9), ...'."""
        return "measured/model per channel: " + ", ".join(
            f"{c} {self.ratios[c]:.3g} (χ²/dof {self.chi2_per_dof[c]:.3g})" for c in self.ratios)

    def as_dict(self) -> dict:
        """JSON-able form for results and reports."""
        return {"ok": self.ok, "findings": [f.as_dict() for f in self.findings],
                "ratios": {k: float(v) for k, v in self.ratios.items()},
                "chi2_per_dof": {k: float(v) for k, v in self.chi2_per_dof.items()},
                "chi2_threshold": self.chi2_threshold,
                "hypotheses": [[h, float(m)] for h, m in self.hypotheses], "notes": list(self.notes),
                "n_points": self.n_points, "n_failed": self.n_failed}


# ----------------------------------------------------------------------------- fitting one hypothesis
@dataclass
class _Fit:
    label: str
    misfit: float
    factors: np.ndarray          # per channel, read / meant (1 = as read)
    ratios: np.ndarray           # per channel, median measured/model
    chi2_per_dof: np.ndarray     # per channel, after dividing by ``factors``
    n_failed: int
    n_ratio: np.ndarray          # per channel, points behind the median ratio
    status_summary: str = ""
    condition: str | None = None
    condition_factor: float = 1.0


def _nearest_factor(ratios: np.ndarray, tolerance: float) -> tuple[float, float]:
    """(median ratio, the signed unit factor it is near, or 1 when none) of one channel."""
    if ratios.size == 0:
        return float("nan"), 1.0
    med = float(np.median(ratios))
    if not np.isfinite(med) or med == 0.0:
        return med, 1.0
    sign = np.sign(med)
    candidates = np.array((1.0,) + CHANNEL_FACTORS)
    distance = np.abs(np.log(abs(med) / candidates))
    f = sign * float(candidates[int(np.argmin(distance))])
    if distance.min() > np.log1p(tolerance) or f == 1.0:
        return med, 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        agree = np.abs(np.log(ratios / f)) <= np.log1p(tolerance)   # NaN (other sign) counts as disagreeing
    return med, (f if np.mean(agree) >= 0.5 else 1.0)


def _fit(label: str, y: np.ndarray, ok: np.ndarray, z: np.ndarray, sigma: np.ndarray | None, *,
         relative_sigma: float, model_error: float, factor_tolerance: float, failure_cost: float,
         search_factors: bool = True) -> _Fit:
    """Misfit of the data ``z`` against model values ``y`` (points ``ok``), per the module docstring;
    with ``search_factors`` each channel may be divided by a unit factor its ratio is near."""
    n_pts, n_ch = z.shape
    factors, ratios, chi2 = np.ones(n_ch), np.full(n_ch, np.nan), np.full(n_ch, np.nan)
    n_ratio = np.zeros(n_ch, int)
    total = 0.0
    for c in range(n_ch):
        use = ok & np.isfinite(z[:, c])
        yc, zc = y[use, c], z[use, c]
        if yc.size == 0:
            continue
        big = (np.abs(yc) >= _USABLE * np.abs(yc).max()) & (yc != 0)
        n_ratio[c] = int(np.count_nonzero(big))
        ratios[c], f = _nearest_factor(zc[big] / yc[big], factor_tolerance)
        factors[c] = f if search_factors else 1.0
        s_meas = sigma[use, c] / abs(factors[c]) if sigma is not None else relative_sigma * np.abs(yc)
        floor = _FLOOR * max(float(np.sqrt(np.mean(yc ** 2))), np.finfo(float).tiny)
        s_eff = np.sqrt(s_meas ** 2 + (model_error * yc) ** 2 + floor ** 2)
        r2 = ((zc / factors[c] - yc) / s_eff) ** 2
        chi2[c] = float(np.mean(r2))
        total += float(np.sum(r2))
    n_failed = int(np.count_nonzero(~ok))
    misfit = (total + failure_cost * n_failed * n_ch) / (n_pts * n_ch)
    return _Fit(label, misfit, factors, ratios, chi2, n_failed, n_ratio)


# ----------------------------------------------------------------------------- words
def _factor_words(factor: float) -> str:
    """'0.001 (10⁻³, a k prefix)', '9.549 (30/π, rpm ↔ rad/s)', '3.6 (km/h ↔ m/s)', '-1'."""
    a = abs(factor)
    text = f"{factor:.4g}"
    for f, up, down, words in _FACTOR_WORDS:
        for exact, name in ((abs(a / f - 1) < 1e-6, up), (abs(a * f - 1) < 1e-6, down)):
            if exact:
                return f"{text} ({words})" if name == text else f"{text} ({name}, {words})"
    return text


def _unit_meant(quantity: str | None, unit_read: str | None, factor: float) -> str | None:
    """The unit whose numbers, read as ``unit_read``, come out ``factor`` times too large."""
    if quantity is None or unit_read is None or quantity not in UNITS or unit_read not in UNITS[quantity]:
        return None
    meant = UNITS[quantity][unit_read] / abs(factor)
    for u, f in UNITS[quantity].items():
        if abs(f / meant - 1) < 1e-6 and u != unit_read:
            return u
    return None


def _unit_read(measurements: Measurements, name: str, quantity: str | None,
               model_unit: str | None) -> tuple[str | None, str]:
    """(unit the values are in as read, how it is known: 'header', 'assumed' or 'memory')."""
    units = measurements.metadata.get("units") if isinstance(measurements.metadata, dict) else None
    if units is None:                                    # not read from a file
        return (si_unit(quantity) if quantity is not None else model_unit), "memory"
    if units.get(name) is not None:
        return units[name], "header"
    return (si_unit(quantity) if quantity is not None else model_unit), "assumed"


def _describe(name: str, quantity: str | None, unit_read: str | None, known_by: str,
              factor: float) -> tuple[str, str]:
    """(headline, what to do) of a quantity whose numbers are ``factor`` times the meant ones."""
    meant = _unit_meant(quantity, unit_read, factor)
    if meant is None:
        a = abs(factor)
        size, times = ("larger", a) if a > 1 else ("smaller", 1 / a)
        return f"{name} is {times:.4g} times {size} than the model expects", ""
    head = f"{name} looks like {meant} read as {unit_read}"
    if known_by == "assumed":
        head += " (the header gives no unit, so SI was assumed)"
    fix = f"; if the numbers are in {meant}, write the header as '{name} [{meant}]'" if known_by != "memory" else ""
    return head, fix


def _model_side(name: str, model_units: str | None) -> str:
    """The model-side cause of a channel ratio, where the user sets the model's units."""
    if model_units is None:
        return ""
    return f"; or the model side: the scale/unit mapped to {name!r} in {model_units}"


def _hypothesis_label(name: str, factor: float) -> str:
    return f"{name} / {factor:.4g}" if factor > 1 else f"{name} x {1 / factor:.4g}"


# ----------------------------------------------------------------------------- the check
def _corrected(conditions: OperatingConditions, name: str, factor: float) -> OperatingConditions:
    values = {f: getattr(conditions, f) for f in CONDITION_FIELDS}
    values[name] = values[name] / factor
    return OperatingConditions(**values)


def _condition_hypotheses(evaluate, measurements: Measurements, conditions, z, kw: dict, notes: list) -> list:
    """The fits with each condition's unit factors applied (:data:`CONDITION_FACTORS`); a condition that is 0
    everywhere, or a hypothesis the model cannot evaluate, is a note instead."""
    fits = []
    for name in conditions:
        if np.all(getattr(measurements.conditions, name) == 0):
            notes.append(f"{name} is 0 at every point: a unit mistake in it cannot be seen")
            continue
        for factor in CONDITION_FACTORS[name]:
            label = _hypothesis_label(name, factor)
            try:
                y, ok, status, sig = evaluate(_corrected(measurements.conditions, name, factor))
            except CalibError as e:
                notes.append(f"hypothesis {label} could not be evaluated: {e}")
                continue
            fit = _fit(label, y, ok, z, sig, **kw)
            fit.condition, fit.condition_factor, fit.status_summary = name, factor, status
            fits.append(fit)
    return fits


def _findings(chosen: "_Fit", base: "_Fit", measurements: Measurements, units: dict, model_units: str | None,
              chi2_threshold: float, model_error: float) -> list:
    """What the chosen hypothesis says: a condition's unit factor, a channel's factor or sign, a misfit no
    factor explains (gross when beyond any polar correction), the model failing at most points."""
    findings = []
    if chosen.condition is not None:
        name, factor = chosen.condition, chosen.condition_factor
        quantity = _CONDITION_SI[name]
        head, fix = _describe(name, quantity, *_unit_read(measurements, name, quantity, None), factor)
        how = f"divided by {factor:.4g}" if factor > 1 else f"multiplied by {1 / factor:.4g}"
        findings.append(UnitFinding(
            "condition", name, factor,
            f"{head}: suspected factor {_factor_words(factor)}; with {name} {how} the nominal model matches the "
            f"data (χ²/dof {chosen.misfit:.3g} instead of {base.misfit:.3g} as read){fix}"))
    for c, name in enumerate(measurements.channels):
        f = chosen.factors[c]
        if f == 1.0:
            continue
        ratio = f"measured/model ≈ {chosen.ratios[c]:.4g} (median over {chosen.n_ratio[c]} points)"
        if f == -1.0:
            findings.append(UnitFinding("sign", name, f, f"{name} has the opposite sign of the model's: {ratio}; "
                                                         "check its sign convention"))
            continue
        quantity = quantity_of(name)
        head, fix = _describe(name, quantity, *_unit_read(measurements, name, quantity, units.get(name)), f)
        findings.append(UnitFinding("channel", name, f, f"{head}: {ratio}, suspected factor {_factor_words(f)}{fix}"
                                                        f"{_model_side(name, model_units)}"))
    for c, name in enumerate(measurements.channels):
        if chosen.chi2_per_dof[c] > chi2_threshold:
            after = " after the correction above" if chosen is not base or chosen.factors[c] != 1.0 else ""
            ratio = abs(chosen.ratios[c] / chosen.factors[c])
            if not 1 / GROSS_RATIO <= ratio <= GROSS_RATIO:      # beyond what any polar correction gives
                findings.append(UnitFinding(
                    "gross", name, float("nan"),
                    f"{name} is {chosen.ratios[c]:.3g} times the nominal model's (median over the points), χ²/dof = "
                    f"{chosen.chi2_per_dof[c]:.3g}{after}: no unit factor explains it exactly, but no calibration "
                    f"of the polars can either (outside 1/{GROSS_RATIO:g} to {GROSS_RATIO:g}); check the unit in the "
                    f"header, what the channel measures and the rotor{_model_side(name, model_units)}"))
                continue
            findings.append(UnitFinding(
                "misfit", name, float("nan"),
                f"{name} disagrees with the nominal model beyond what noise and a {model_error:.0%} model error "
                f"explain: χ²/dof = {chosen.chi2_per_dof[c]:.3g}{after} (threshold {chi2_threshold:g}), "
                f"measured/model ≈ {chosen.ratios[c]:.3g}, and no unit factor explains it; check the unit in "
                f"the header, what the channel measures (e.g. electrical or aerodynamic power) and the rotor"
                f"{_model_side(name, model_units)}"))
    if chosen.n_failed > 0.5 * measurements.n_points:
        findings.append(UnitFinding("failures", "", float("nan"),
                                    f"the nominal model fails at {chosen.n_failed} of {measurements.n_points} "
                                    f"measured points ({chosen.status_summary}): check the conditions' units"))
    return findings


def check_units(model, p, measurements: Measurements, *, sigma: Mapping[str, float] | None = None,
                chi2_threshold: float = 25.0, model_error: float = 0.10, relative_sigma: float = 0.05,
                factor_tolerance: float = 0.25,
                conditions: Sequence[str] = ("wind_speed", "rotor_speed", "pitch"),
                model_units: str | None = None) -> UnitCheckReport:
    """Compare measurements with the nominal model to catch unit mistakes before calibrating.

    Parameters
    ----------
    model : ForwardModel
        Any model of the contract (only ``channels`` and ``evaluate`` are used).
    p : array_like, shape (n_params,)
        Parameters to compare at, normally the nominal vector.
    measurements : Measurements
        Channels must be outputs of ``model``.
    sigma : mapping channel -> float, optional
        1-σ noise per channel [channel unit] overriding the table's (the calibration's
        ``sigma`` setting); channels not in it keep the table's σ or ``relative_sigma``.
    chi2_threshold : float
        χ²/dof per channel beyond which a channel is a finding [-] (default 25: with the
        model allowance below, an RMS disagreement of about 50 %).
    model_error : float
        Relative error allowed to the uncalibrated model in χ² [-] (default 0.10); 0 gives the
        plain χ² with the measurement noise.
    relative_sigma : float
        Noise assumed where no σ is known, as a fraction of the model value [-] (default 0.05).
    factor_tolerance : float
        A ratio r is "near" a factor f when r/f is within [1/(1+tol), 1+tol] [-].
    conditions : sequence of str
        Conditions whose unit factors (:data:`CONDITION_FACTORS`) are tried.
    model_units : str, optional
        Where the user set the model's output units, when they are set outside the model
        (an FMU's mapping file); channel findings then name its ``scale``/``unit`` as a
        possible cause beside the measurement header.

    Returns
    -------
    UnitCheckReport

    Raises
    ------
    InputError
        A measured channel the model does not provide; an unknown condition name; σ <= 0.
    CalibError
        The model cannot be evaluated at the conditions as read.

    Notes
    -----
    See the module docstring for the method. Cost: one model evaluation, plus two per
    checked condition that is not zero everywhere (seven for the default).
    """
    for name in conditions:
        if name not in CONDITION_FACTORS:
            raise InputError(f"no unit factors known for condition {name!r}; valid: "
                             f"{', '.join(CONDITION_FACTORS)}", "check_units", field="conditions")
    model_channels = [c.name for c in model.channels]
    check_channels(measurements, model_channels)
    idx = [model_channels.index(c) for c in measurements.channels]
    units = {c.name: c.unit for c in model.channels}
    z = measurements.values
    p = np.asarray(p, float)
    notes = []
    s = None if measurements.sigma is None else measurements.sigma.copy()
    if sigma:
        s = np.full(z.shape, np.nan) if s is None else s
        for name, value in sigma.items():
            if name in measurements.channels:
                if not float(value) > 0:
                    raise InputError(f"sigma must be > 0, got {value!r}", "check_units", field=f"sigma.{name}")
                s[:, measurements.channels.index(name)] = float(value)
    unknown = [c for k, c in enumerate(measurements.channels) if s is None or np.isnan(s[:, k]).any()]
    if unknown:
        notes.append(f"no σ for {', '.join(unknown)}: {relative_sigma:.0%} of the model value used")
    notes.append(f"χ² allows the uncalibrated model a {model_error:.0%} error (model_error)")
    kw = dict(relative_sigma=relative_sigma, model_error=model_error, factor_tolerance=factor_tolerance,
              failure_cost=chi2_threshold)

    def evaluate(cond):
        ev = model.evaluate(p, cond)
        y = np.asarray(ev.values, float)[:, idx]
        sig = None if s is None else np.where(np.isnan(s), relative_sigma * np.abs(y), s)  # NaN: no σ given
        return y, np.asarray(ev.ok) & np.all(np.isfinite(y), axis=1), ev.failure_summary(), sig

    y0, ok0, status0, sig0 = evaluate(measurements.conditions)
    as_read = _fit("as read", y0, ok0, z, sig0, search_factors=False, **kw)
    base = _fit("as read", y0, ok0, z, sig0, **kw)
    base.status_summary = status0
    fits = [base] + _condition_hypotheses(evaluate, measurements, conditions, z, kw, notes)
    best = min(fits, key=lambda f: f.misfit)
    explained = (best is not base and base.misfit > 1.0 and best.misfit <= chi2_threshold
                 and best.misfit * _EXPLAIN_GAIN <= base.misfit)
    chosen = best if explained else base

    findings = _findings(chosen, base, measurements, units, model_units, chi2_threshold, model_error)
    return UnitCheckReport(
        findings=tuple(findings),
        ratios={c: float(as_read.ratios[k]) for k, c in enumerate(measurements.channels)},
        chi2_per_dof={c: float(as_read.chi2_per_dof[k]) for k, c in enumerate(measurements.channels)},
        chi2_threshold=float(chi2_threshold), hypotheses=tuple((f.label, float(f.misfit)) for f in fits),
        notes=tuple(notes), source=measurements.source, n_points=measurements.n_points,
        n_failed=base.n_failed)


# ----------------------------------------------------------------------------- the gate before a run
def apply_unit_check(model, p, measurements: Measurements, *, sigma: Mapping[str, float] | None = None,
                     force: bool = False, strict: bool = False, source: str | None = None,
                     printer=print, prefix: str = "[calib run]", model_units: str | None = None,
                     ) -> tuple[UnitCheckReport, dict]:
    """Run :func:`check_units` before a calibration or diagnosis, print it, stop or go on.

    A finding that a unit factor or a sign explains stops the run (unless ``force``); a misfit
    that no unit factor explains is printed as a warning and the run goes on (unless
    ``strict``). ``calib run`` and ``calib diagnose`` both call this, so their messages agree.

    Parameters
    ----------
    model, p, measurements, sigma, model_units
        As :func:`check_units`.
    force : bool
        Go on whatever the check finds (``--force``); the notes say what was overridden.
    strict : bool
        Also stop on a misfit no unit factor explains (``--strict-units``).
    source : str, optional
        File named in the error (default: the measurements' source).
    printer : callable(str)
        Receives each line (the summary, then any warning).
    prefix : str
        Put before each printed line (the command's name).

    Returns
    -------
    report : UnitCheckReport
    notes : dict
        Lines for the result's checks and the report: the misfit warning, or what ``force``
        overrode; empty when the check passed.

    Raises
    ------
    InputError
        When a unit factor explains a finding (or, with ``strict``, on any finding) and not
        ``force``; it names the file, the channel or condition and the suspected factor.
    """
    report = check_units(model, p, measurements, sigma=sigma, model_units=model_units)
    for line in report.summary().splitlines():
        printer(f"{prefix} {line}")
    if not force:
        report.raise_if_failed(source, strict=strict)
    notes = {}
    if force and (report.unit_findings or (strict and report.misfit_findings)):
        notes["unit check (overridden by force)"] = "; ".join(f.message for f in report.findings)
    elif report.misfit_findings:
        for line in report.warning_lines():
            printer(f"{prefix} {line}")
        notes["unit check: misfit no unit factor explains (calibrated anyway)"] = report.ratio_words()
    return report, notes
