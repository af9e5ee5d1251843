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
   ``factor_tolerance`` of a unit factor f ≠ 1 (:data:`~calib.checks.unit_findings.CHANNEL_FACTORS`, either sign) and at
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
- ``gross``: a channel misfit whose ratio lies outside 1/5 to 5 (:data:`~calib.checks.unit_findings.GROSS_RATIO`) without
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

Here: the hypotheses and their fits (:func:`check_units`) and the gate before a run
(:func:`apply_unit_check`). The unit factors, the findings in words and the report are in
:mod:`calib.checks.unit_findings`.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from calib.checks.unit_findings import CHANNEL_FACTORS, CONDITION_FACTORS, UnitCheckReport, UnitFit, findings_of
from calib.errors import CalibError, InputError
from calib.measurements import Measurements, check_channels
from calib.types import CONDITION_FIELDS, OperatingConditions

__all__ = ["apply_unit_check", "check_units"]

_EXPLAIN_GAIN = 10.0       # a hypothesis must lower the misfit this many times to explain the data
_USABLE = 0.1              # ratios from points with |model| >= this x the channel's largest |model|
_FLOOR = 1e-3              # σ floor as a fraction of the channel's RMS model value


# ----------------------------------------------------------------------------- fitting one hypothesis
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
         search_factors: bool = True) -> UnitFit:
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
    return UnitFit(label, misfit, factors, ratios, chi2, n_failed, n_ratio)


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
    See the module docstring for the method. Cost: one model evaluation; when the data do not
    fit as read (misfit > 1), two more per checked condition that is not zero everywhere (seven
    for the default). Data that fit as read cannot be explained better by a condition factor
    (step 4), so those hypotheses are not evaluated then.
    """
    _check_condition_names(conditions)
    model_channels = [c.name for c in model.channels]
    check_channels(measurements, model_channels)
    idx = [model_channels.index(c) for c in measurements.channels]
    units = {c.name: c.unit for c in model.channels}
    p = np.asarray(p, float)
    notes = []
    s = _noise(measurements, sigma, relative_sigma, notes)
    notes.append(f"χ² allows the uncalibrated model a {model_error:.0%} error (model_error)")
    kw = dict(relative_sigma=relative_sigma, model_error=model_error, factor_tolerance=factor_tolerance,
              failure_cost=chi2_threshold)
    evaluate = _evaluator(model, p, idx, s, relative_sigma)
    as_read, base, fits, chosen = _hypotheses(evaluate, measurements, conditions, kw, chi2_threshold, notes)
    findings = findings_of(chosen, base, measurements, units, model_units, chi2_threshold, model_error)
    return UnitCheckReport(
        findings=tuple(findings),
        ratios={c: float(as_read.ratios[k]) for k, c in enumerate(measurements.channels)},
        chi2_per_dof={c: float(as_read.chi2_per_dof[k]) for k, c in enumerate(measurements.channels)},
        chi2_threshold=float(chi2_threshold), hypotheses=tuple((f.label, float(f.misfit)) for f in fits),
        notes=tuple(notes), source=measurements.source, n_points=measurements.n_points,
        n_failed=base.n_failed, model_error=float(model_error))


def _check_condition_names(conditions: Sequence[str]) -> None:
    """Raise :class:`~calib.errors.InputError` for a condition without unit factors (:data:`CONDITION_FACTORS`)."""
    for name in conditions:
        if name not in CONDITION_FACTORS:
            raise InputError(f"no unit factors known for condition {name!r}; valid: "
                             f"{', '.join(CONDITION_FACTORS)}", "check_units", field="conditions")


def _noise(measurements: Measurements, sigma: Mapping[str, float] | None, relative_sigma: float,
           notes: list) -> np.ndarray | None:
    """The 1-σ noise per point and channel: the table's, overridden per channel by ``sigma``.

    Parameters
    ----------
    measurements : Measurements
    sigma : mapping channel -> float, optional
        As :func:`check_units` [channel unit].
    relative_sigma : float
        Named in the note on channels without σ [-].
    notes : list of str
        Receives that note.

    Returns
    -------
    ndarray, shape (n_points, n_channels), or None
        NaN where no σ is known; None when none is known anywhere [channel unit].

    Raises
    ------
    InputError
        A σ in ``sigma`` that is not > 0.
    """
    s = None if measurements.sigma is None else measurements.sigma.copy()
    if sigma:
        s = np.full(measurements.values.shape, np.nan) if s is None else s
        for name, value in sigma.items():
            if name in measurements.channels:
                if not float(value) > 0:
                    raise InputError(f"sigma must be > 0, got {value!r}", "check_units", field=f"sigma.{name}")
                s[:, measurements.channels.index(name)] = float(value)
    unknown = [c for k, c in enumerate(measurements.channels) if s is None or np.isnan(s[:, k]).any()]
    if unknown:
        notes.append(f"no σ for {', '.join(unknown)}: {relative_sigma:.0%} of the model value used")
    return s


def _evaluator(model, p: np.ndarray, idx: list, s: np.ndarray | None, relative_sigma: float):
    """``evaluate(conditions) -> (y, ok, failure summary, σ)``: the model at ``p`` on the measured channels.

    ``y`` holds the model's channels ``idx`` (the measured ones, in their order); ``ok`` the points
    that converged with finite values; σ is ``s`` with ``relative_sigma`` × |y| where it is NaN
    (None when ``s`` is).
    """
    def evaluate(cond):
        ev = model.evaluate(p, cond)
        y = np.asarray(ev.values, float)[:, idx]
        sig = None if s is None else np.where(np.isnan(s), relative_sigma * np.abs(y), s)  # NaN: no σ given
        return y, np.asarray(ev.ok) & np.all(np.isfinite(y), axis=1), ev.failure_summary(), sig

    return evaluate


def _hypotheses(evaluate, measurements: Measurements, conditions: Sequence[str], kw: dict,
                chi2_threshold: float, notes: list) -> tuple[UnitFit, UnitFit, list, UnitFit]:
    """Fit every hypothesis and choose the one that explains the data (steps 1–4 of the module docstring).

    Returns
    -------
    as_read : UnitFit
        The conditions and channels as read (no unit factor searched).
    base : UnitFit
        The conditions as read, each channel divided by the unit factor its ratio is near.
    fits : list of UnitFit
        ``base``, then every condition hypothesis.
    chosen : UnitFit
        The best condition hypothesis where it explains the data, else ``base``.
    """
    z = measurements.values
    y0, ok0, status0, sig0 = evaluate(measurements.conditions)
    as_read = _fit("as read", y0, ok0, z, sig0, search_factors=False, **kw)
    base = _fit("as read", y0, ok0, z, sig0, **kw)
    base.status_summary = status0
    if base.misfit <= 1.0:
        # no condition hypothesis can explain data that fit as read (step 4): none is evaluated
        notes.extend(f"{name} is 0 at every point: a unit mistake in it cannot be seen" for name in conditions
                     if np.all(getattr(measurements.conditions, name) == 0))
        notes.append(f"the data fit as read (misfit {base.misfit:.3g} <= 1): no condition hypothesis evaluated")
        return as_read, base, [base], base
    fits = [base] + _condition_hypotheses(evaluate, measurements, conditions, z, kw, notes)
    best = min(fits, key=lambda f: f.misfit)
    explained = (best is not base and base.misfit > 1.0 and best.misfit <= chi2_threshold
                 and best.misfit * _EXPLAIN_GAIN <= base.misfit)
    return as_read, base, fits, (best if explained else base)


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
    simulations = _simulation_line(model)
    if simulations:
        printer(f"{prefix} unit check: {simulations}")
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


def _simulation_line(model) -> str | None:
    """What the check's simulations cost, for a model that counts them (an FMU:
    :meth:`calib.fmu.model.FmuModel.simulation_summary`; through a recorded model, the wrapped one)."""
    inner = getattr(model, "wrapped", model)
    summary = getattr(inner, "simulation_summary", None)
    if summary is None:
        return None
    from calib.fmu.tally import tally_sentence
    return "FMU " + tally_sentence(summary())
