"""The candidates of a diagnosis on the native BEM (:class:`BemFamily`): the effects of
:data:`calib.effects.EFFECTS` switched into a :class:`~calib.models.bem_model.BemModel`, one
entry per model form (:func:`_variants`), and a named effect frozen at its fitted values for
the next round (:func:`_fixed_effect`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from calib.diagnosis.settings import NAMEABLE
from calib.effects import EFFECTS, make_effect
from calib.errors import InputError
from calib.models.bem_model import BemModel

if TYPE_CHECKING:
    from calib.diagnosis.result import CandidateFit

#: Spanwise stations r/R of the normal-force probes (:meth:`BemFamily.probe_channels`).
PROBE_STATIONS = (0.3, 0.5, 0.7, 0.9)


def _variants(name: str, options: dict) -> list:
    """(label, effect) for every variant of effect ``name`` (one entry when it has none or the
    options fix it): the model forms of one physical effect compete among themselves, and the
    best one names the effect."""
    cls = EFFECTS[name]
    choices = cls.CHOICES.get("variant")
    if not choices or "variant" in options:
        return [(name, make_effect(name, **options))]
    return [(f"{name}:{v}", make_effect(name, **{**options, "variant": v})) for v in choices]


def facility_effects(dset, rotor) -> list:
    """The corrections the campaign's facility makes known (applied to every model, no free
    parameter): Glauert's blockage at β = swept area / cross-section when ``dset.cross_section``
    [m²] is stated (:class:`calib.effects.wind_tunnel_blockage.WindTunnelBlockage`)."""
    if dset.cross_section is None:
        return []
    ratio = rotor.swept_area / dset.cross_section
    if not ratio < 1.0:
        raise InputError(f"the rotor's swept area {rotor.swept_area:.4g} m² does not fit a cross-section of "
                         f"{dset.cross_section:g} m²", "DiagnosisSettings", field="diagnosis.cross_section")
    return [make_effect("wind_tunnel_blockage", area_ratio=ratio)]


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


class BemFamily:
    """The models a diagnosis on the native BEM calibrates: candidates are the effects of
    :data:`calib.effects.EFFECTS` switched into a :class:`~calib.models.bem_model.BemModel`.

    Every family offers the same few calls, so :func:`calib.diagnosis.core.diagnose` runs
    unchanged on another kind of model (:class:`calib.diagnosis.fmu.FmuFamily`).
    """

    def __init__(self, rotor, channels, grid, settings, rotor_source=None, fixed=()):
        self.rotor, self.channels, self.grid, self.settings = rotor, list(channels), grid, settings
        self.fixed = list(fixed)            # the facility's known corrections (facility_effects), in every model
        self.rotor_source = rotor_source
        self.rotor_radius = rotor.rotor_radius
        self.schedule = rotor.schedule      # the operating limits separation probes keep to (None: unknown)
        self.names = NAMEABLE

    def field_model(self, base=()):
        """The correction field on top of the fixed ``base`` effects (localize, recalibrate)."""
        return BemModel(self.rotor, self.grid, self.channels, self.settings, (), effects=self.fixed + list(base),
                        rotor_source=self.rotor_source)

    def nominal_model(self):
        return BemModel(self.rotor, None, self.channels, self.settings, (), effects=self.fixed,
                        rotor_source=self.rotor_source)

    def variants(self, name: str, options: dict) -> list:
        return _variants(name, options)

    def candidate_model(self, base, effect):
        return BemModel(self.rotor, None, self.channels, self.settings, (), effects=self.fixed + list(base) + [effect])

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
        model = BemModel(self.rotor, None, channels, self.settings, (), effects=self.fixed + list(base) + [effect],
                         rotor_source=self.rotor_source)
        ev = model.evaluate(p, conditions)
        return ev.values, [c.unit for c in model.channels]

    def fingerprint(self, name: str) -> str:
        return EFFECTS[name].fingerprint if name in EFFECTS else ""

    def kind(self, name: str) -> str:
        """"model_form" for a parameter of the BEM's own approximation (its induction model),
        "physical" for a missing effect (:attr:`calib.effects.base.Effect.kind`)."""
        return EFFECTS[name].kind if name in EFFECTS else "physical"
