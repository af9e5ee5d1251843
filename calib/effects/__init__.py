"""Effects the native BEM can switch into its chain, by name.

Each effect is one file here: a small class (:class:`calib.effects.base.Effect`) with its
stage, parameters, formula, reference and fingerprint. :data:`EFFECTS` maps registry
names to classes; :func:`make_effect` builds one by name, :func:`effect_from_spec` from its
``spec()``, and :func:`describe_effects` lists them all with their parameters.

Adding an effect: one file with the class, one entry in :data:`EFFECTS`, one finite-
difference test of its derivatives and one fingerprint test (``tests/test_effects.py``).
"""

from __future__ import annotations

from calib.effects.base import Effect
from calib.effects.correction_field import CorrectionFieldEffect
from calib.effects.leading_edge_erosion import LeadingEdgeErosion
from calib.effects.lift_offset import LiftOffset
from calib.effects.momentum_balance import MomentumBalance
from calib.effects.pitch_offset import PitchOffset
from calib.effects.reynolds_number import ReynoldsNumber
from calib.effects.rotational_augmentation import RotationalAugmentation
from calib.effects.tip_loss import TipLoss
from calib.effects.wind_speed_scale import WindSpeedScale
from calib.effects.wind_tunnel_blockage import WindTunnelBlockage
from calib.errors import InputError

#: Registry name -> effect class.
EFFECTS = {
    "correction_field": CorrectionFieldEffect,
    "pitch_offset": PitchOffset,
    "wind_speed_scale": WindSpeedScale,
    "rotational_augmentation": RotationalAugmentation,
    "leading_edge_erosion": LeadingEdgeErosion,
    "reynolds_number": ReynoldsNumber,
    "tip_loss": TipLoss,
    "wind_tunnel_blockage": WindTunnelBlockage,
    "lift_offset": LiftOffset,
    "momentum_balance": MomentumBalance,
}


def make_effect(name: str, **options) -> Effect:
    """Build the effect registered as ``name`` with its options.

    Raises
    ------
    InputError
        For an unknown name (the message lists the valid ones) or bad options.
    """
    if name not in EFFECTS:
        raise InputError(f"unknown effect {name!r}; valid: {', '.join(EFFECTS)}", "make_effect", field="name")
    return EFFECTS[name](**options)


def effect_from_spec(spec, source: str = "effect spec") -> Effect:
    """An effect from ``{"name": ..., "options": {...}}`` (an effect's ``spec()``), a name, or an Effect."""
    if isinstance(spec, Effect):
        return spec
    if isinstance(spec, str):
        return make_effect(spec)
    if not isinstance(spec, dict) or "name" not in spec:
        raise InputError(f"expected an effect name or a table with 'name' (and 'options'), got {spec!r}", source,
                         field="effects")
    extra = sorted(set(spec) - {"name", "options"})
    if extra:
        raise InputError(f"unknown key(s) {', '.join(map(repr, extra))} in an effect entry; valid: name, options",
                         source, field=extra[0])
    return make_effect(spec["name"], **dict(spec.get("options") or {}))


def describe_effects() -> list[dict]:
    """Every registered effect with its default options, parameters and fingerprint.

    The correction field needs a node grid and is described without parameters.
    """
    out = []
    for name, cls in EFFECTS.items():
        if name == "correction_field":
            out.append({"name": name, "stage": cls.stage, "options": dict(cls.OPTIONS), "parameters": [],
                        "fingerprint": cls.fingerprint})
        else:
            out.append(cls().describe())
    return out


__all__ = ["EFFECTS", "CorrectionFieldEffect", "Effect", "describe_effects", "effect_from_spec", "make_effect"]
