"""What the unit check (:mod:`calib.checks.unit_check`) finds, and how it says so.

The unit factors the check tries (:data:`CHANNEL_FACTORS`, :data:`CONDITION_FACTORS`); each
finding (:class:`UnitFinding`) in words, with the unit meant and the fix to write
(:func:`findings_of`); and the report (:class:`UnitCheckReport`) that stops a run on the kinds in
:data:`STOPPING_KINDS` unless forced, or warns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.errors import InputError
from calib.measurements import UNITS, Measurements, quantity_of, si_unit

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
    """Outcome of :func:`calib.checks.unit_check.check_units`.

    Attributes
    ----------
    findings : tuple of UnitFinding
        Empty when the data look consistent with the model's units.
    ratios : dict channel -> float
        Median measured/model per channel, as read [-].
    chi2_per_dof : dict channel -> float
        χ²/dof per channel as read, with the σ of the :mod:`calib.checks.unit_check` docstring [-].
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
    model_error: float = 0.10

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
        lines = [head, f"  measured/model as read (χ²/dof of the unit check: against the noise σ plus a "
                       f"{self.model_error:.0%} allowance for the uncalibrated model, not the calibration's χ²): {per}"]
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


# ----------------------------------------------------------------------------- the findings
@dataclass
class UnitFit:
    """One unit hypothesis fitted by the unit check (:func:`calib.checks.unit_check.check_units`).

    Attributes
    ----------
    label : str
        The hypothesis in words ("as read", "power in kW", ...).
    misfit : float
        Mean squared whitened residual over all points and channels, a failed model evaluation
        costing the check's failure cost per channel [-].
    factors : ndarray, shape (n_channels,)
        Unit factor per channel, read / meant (1 = as read) [-].
    ratios : ndarray, shape (n_channels,)
        Median measured / model per channel [-].
    chi2_per_dof : ndarray, shape (n_channels,)
        Per channel, after dividing by ``factors``, against the check's model-error allowance [-].
    n_failed : int
        Model evaluations that failed.
    n_ratio : ndarray of int, shape (n_channels,)
        Points behind each median ratio.
    status_summary : str
        The model's status counts in words.
    condition : str or None
        The operating condition whose unit the hypothesis changes, if any.
    condition_factor : float
        Its factor, read / meant [-].
    """

    label: str
    misfit: float
    factors: np.ndarray
    ratios: np.ndarray
    chi2_per_dof: np.ndarray
    n_failed: int
    n_ratio: np.ndarray
    status_summary: str = ""
    condition: str | None = None
    condition_factor: float = 1.0


def findings_of(chosen: UnitFit, base: UnitFit, measurements: Measurements, units: dict, model_units: str | None,
                chi2_threshold: float, model_error: float) -> list:
    """What the chosen hypothesis says: a condition's unit factor, a channel's factor or sign, a misfit no
    factor explains (gross when beyond any polar correction), the model failing at most points.

    Parameters
    ----------
    chosen, base : UnitFit
        The hypothesis chosen, and the one with the conditions as read.
    measurements : Measurements
    units : dict channel -> str
        The model's output units.
    model_units, chi2_threshold, model_error
        As :func:`calib.checks.unit_check.check_units`.

    Returns
    -------
    list of UnitFinding
    """
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
