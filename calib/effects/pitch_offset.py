"""Collective pitch offset: the blades sit at β + Δβ instead of the measured β."""

from __future__ import annotations

from calib.effects.base import Effect
from calib.types import Parameter


class PitchOffset(Effect):
    """A collective pitch offset (conditions stage): β → β + Δβ.

    Parameters
    ----------
    nominal : dict, optional
        ``{"pitch_offset": value}`` [deg].

    Notes
    -----
    .. math:: β' = β + Δβ

    An encoder zero error or a blade mounted off its mark. It moves every section's angle of
    attack by −Δβ, so it looks like a uniform α shift of the polars.

    Fingerprint: the measured C_P(λ, β) surface is the model's shifted along β by Δβ; the
    same shift at every λ and wind speed.
    """

    name = "pitch_offset"
    stage = "conditions"
    fingerprint = "looks like a uniform alpha shift of the polars; shifts C_P(lambda, beta) along beta"
    PARAMETERS = (Parameter("pitch_offset", 0.0, -5.0, 5.0, 0.5, "deg", "nuisance",
                            description="collective pitch offset added to the measured pitch", prior_std=2.0),)

    def apply(self, theta, inflow, ctx):
        (offset,) = theta
        return inflow.replace(pitch=inflow.pitch + offset)
