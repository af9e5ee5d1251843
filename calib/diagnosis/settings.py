"""Settings of the diagnosis (:class:`DiagnosisSettings`): which candidate effects
are tried, how many may be named, the significance and ambiguity thresholds, and the
model-form tolerance (:data:`MODEL_FORM_TOLERANCE`) the naming step allows the nominal model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from calib.effects import EFFECTS
from calib.errors import InputError

#: Effects the native BEM can name (the correction field is the localizer, not a candidate).
NAMEABLE = tuple(n for n in EFFECTS if n != "correction_field")

#: Default model-form tolerance [-]: the RMS relative difference between calib's native BEM and an
#: independent code, WISDEM's CCBlade 4.2.9, on the same rotor and polars (NREL 5-MW, 63 operating
#: points of the out-of-family battery, no effect, no noise; the larger of the rigid and the
#: tilted/coned set-up; benchmarks/bench_oof_battery.py, measured 2026-11-25), rounded up. The
#: difference is CCBlade's smoothing spline on the polars (below 5e-5 with calib's polar_smoothing
#: of the same spline). root_flap_moment takes the hub flap moment's (the same loads about another
#: point); other channels not measured take the largest ("default").
MODEL_FORM_TOLERANCE = {"power": 0.0097, "torque": 0.0097, "thrust": 0.0024, "hub_flap_moment": 0.0029,
                        "root_flap_moment": 0.0029, "default": 0.0097}


#: Where a campaign was measured (``[diagnosis] facility``): "unstated" keeps every candidate.
FACILITIES = ("unstated", "field", "wind_tunnel", "towing_tank")
#: Effects that need walls around the flow: not candidates of a campaign in the field.
WALLED_EFFECTS = ("wind_tunnel_blockage",)


@dataclass(frozen=True)
class DiagnosisSettings:
    """Settings of :func:`calib.diagnosis.core.diagnose`.

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
    facility : str
        Where the campaign was measured (:data:`FACILITIES`): in the ``field`` no effect of
        :data:`WALLED_EFFECTS` is a candidate (a free-field rotor has no tunnel walls); in a
        ``wind_tunnel`` or ``towing_tank`` blockage is estimated, or applied at the known area
        ratio when ``cross_section`` is stated. Default "unstated" (every candidate is tried).
    cross_section : float, optional
        The test section's (or tank's) cross-section area [m²], ``wind_tunnel`` and
        ``towing_tank`` only: Glauert's blockage correction is then part of every model at
        β = swept area / cross-section, and blockage is no longer a candidate.
    """

    candidates: tuple | None = None
    candidate_options: dict = field(default_factory=dict)
    max_effects: int = 2
    significance: float = 0.01
    ambiguity_bic: float = 6.0
    ambiguity_pattern: float = 0.1
    recalibrate: bool = True
    model_form_tolerance: float | dict = field(default_factory=lambda: dict(MODEL_FORM_TOLERANCE))
    facility: str = "unstated"
    cross_section: float | None = None

    def excluded(self) -> dict[str, str]:
        """The candidates the facility rules out: {effect: why}."""
        if self.facility == "field":
            return {n: "a field campaign has no tunnel walls (facility = \"field\")" for n in WALLED_EFFECTS}
        if self.cross_section is not None:
            return {n: f"its area ratio is known from the stated cross-section ({self.cross_section:g} m²) and "
                       "applied to every model" for n in WALLED_EFFECTS}
        return {}

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
        need(self.facility in FACILITIES, "facility", "one of " + ", ".join(FACILITIES))
        need(self.cross_section is None or (number(self.cross_section) and self.cross_section > 0),
             "cross_section", "a cross-section area > 0 [m²]")
        if self.cross_section is not None and self.facility not in ("wind_tunnel", "towing_tank"):
            raise InputError(f"a cross-section needs facility = \"wind_tunnel\" or \"towing_tank\", got "
                             f"facility = {self.facility!r}", source, field=f"{prefix}cross_section")
        names = self.candidates if self.candidates is not None else valid
        ruled_out = [c for c in names if c in self.excluded()] if self.candidates is not None else []
        if ruled_out:
            raise InputError(f"candidate {ruled_out[0]} is ruled out: {self.excluded()[ruled_out[0]]}; remove it "
                             "from candidates", source, field=f"{prefix}candidates")
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
