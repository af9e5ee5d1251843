"""What a diagnosis returns: one fitted candidate effect (:class:`CandidateFit`, a row of the
candidate table) and the whole :class:`Diagnosis` (``diagnosis.json``)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np


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
    start: str = ""                     # the second start, when one ran (calib.diagnosis.naming.fit_task): "second start kept (...)"
    p_hat: np.ndarray | None = None     # every fitted parameter (base effects' too) [parameter units]
    kind: str = "physical"              # "model_form": the BEM's own approximation (calib.effects.base.Effect.kind)

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
    """What :func:`calib.diagnosis.core.diagnose` found (``to_dict`` is ``diagnosis.json``)."""

    effect: str
    effects: list
    rounds: list                       # per naming round: {"candidates": [CandidateFit], "verdict": ...}
    before: dict
    with_effects: dict
    after: dict
    find: dict
    localization: object               # CalibrationResult of the correction field alone (None: not run, see core)
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
    setup: list = field(default_factory=list)   # calib.report.setup_statement.SetupItem: the set-up in force
    model_form: list = field(default_factory=list)  # model-form parameters named (in ``effects`` too), in order
    channel_units: list = field(default_factory=list)   # units of ``channels``, as the model states them

    @property
    def candidates(self) -> list:
        """The first round's candidates (the comparison against the nominal model)."""
        return self.rounds[0]["candidates"] if self.rounds else []

    @property
    def named_first(self) -> str:
        """The first effect named, physical or model form; else ``effect`` (``none``, ``ambiguous``)."""
        return self.effects[0] if self.effects and self.effect != "ambiguous" else self.effect

    @property
    def ambiguous(self) -> list:
        """The two effects the last round could not tell apart ([] unless ``effect`` is ``ambiguous``);
        ``effects`` holds only those added to the model, by the rounds before."""
        return list(self.rounds[-1].get("ambiguous", [])) if self.rounds and self.effect == "ambiguous" else []

    def to_dict(self) -> dict:
        return {"effect": self.effect, "effects": self.effects, "model_form": self.model_form,
                "ambiguous": self.ambiguous,
                "candidates": [c.to_dict() for c in self.candidates],
                "rounds": [{"base": r["base"], "verdict": r["verdict"], "reason": r["reason"],
                            **{k: r[k] for k in ("ambiguous", "separate", "shares") if k in r},
                            "candidates": [c.to_dict() for c in r["candidates"]]} for r in self.rounds],
                "before": self.before, "with_effects": self.with_effects, "after": self.after,
                "find": self.find, "channels": self.channels, "wall_time": self.wall_time, "notes": self.notes,
                "failure": self.failure, "setup": [i.as_dict() for i in self.setup],
                "localization": None if self.localization is None else {
                    "n_retained": self.localization.n_retained,
                    "chi2_per_dof_after": self.localization.chi2_per_dof_after,
                    "status": self.localization.estimate.status},
                "recalibration": None if self.recalibration is None else {
                    "n_retained": self.recalibration.n_retained, "status": self.recalibration.estimate.status,
                    "chi2_per_dof_after": self.recalibration.chi2_per_dof_after}}
