"""Measurement uncertainty items a user states (IEC 61400-12-1 category B style), per bin.

Each item is a relative standard uncertainty of one quantity, turned into a power uncertainty
per bin with its sensitivity coefficient (IEC 61400-12-1, Annex D/E):

- ``wind`` (anemometer calibration, mounting, flow distortion): u_P = |dP/dV| · u_V, u_V = r · V;
- ``density`` (air-density measurement): the standard normalizes the wind speed of a
  pitch-regulated turbine by (ρ/ρ₀)^{1/3}, so u_V = r/3 · V and u_P = |dP/dV| · u_V;
- ``power`` (power transducer, current and voltage transformers): u_P = r · P.

Items are independent of each other (added in quadrature within a bin) and, as the standard
treats category B, fully correlated across bins (added linearly in the AEP).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from calib.errors import InputError

__all__ = ["MEASUREMENT_KINDS", "MeasurementItem", "parse_measurement"]

MEASUREMENT_KINDS = ("wind", "density", "power")


@dataclass(frozen=True)
class MeasurementItem:
    """One stated measurement uncertainty.

    Parameters
    ----------
    name : str
    kind : str
        ``"wind"``, ``"density"`` or ``"power"``.
    relative : float
        Relative standard uncertainty (1-σ) of the quantity [-], e.g. 0.02 for 2 %.
    """

    name: str
    kind: str
    relative: float

    def power_std(self, wind_speed, power) -> np.ndarray:
        """u_P per bin [W] for a power curve ``power`` [W] at bin centres ``wind_speed`` [m/s]."""
        v, P = np.asarray(wind_speed, float), np.asarray(power, float)
        if self.kind == "power":
            return self.relative * np.abs(P)
        slope = np.gradient(np.nan_to_num(P), v)
        u_v = self.relative * v / (3.0 if self.kind == "density" else 1.0)
        return np.abs(slope) * u_v

    def words(self) -> str:
        what = {"wind": "of wind speed", "density": "of air density (as a wind-speed normalization, /3)",
                "power": "of power"}[self.kind]
        return f"{self.name}: {100 * self.relative:g} % {what}"


def parse_measurement(text: str) -> MeasurementItem:
    """``NAME=KIND:PERCENT`` (``anemometer=wind:2``, ``transducer=power:0.5%``) as a :class:`MeasurementItem`.

    Raises
    ------
    InputError
        Naming ``--measurement`` and the valid kinds.
    """
    m = re.fullmatch(r"\s*([^=]+?)\s*=\s*(\w+)\s*:\s*([-+0-9.eE]+)\s*%?\s*", text or "")
    if not m:
        raise InputError(f"--measurement {text!r}: expected NAME=KIND:PERCENT, e.g. anemometer=wind:2 "
                         f"(kinds: {', '.join(MEASUREMENT_KINDS)})", "--measurement", field="measurement")
    name, kind, pct = m.group(1), m.group(2), m.group(3)
    if kind not in MEASUREMENT_KINDS:
        raise InputError(f"--measurement {text!r}: unknown kind {kind!r}; valid: {', '.join(MEASUREMENT_KINDS)}",
                         "--measurement", field="measurement")
    try:
        value = float(pct)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value) or value < 0:
        raise InputError(f"--measurement {text!r}: the percentage must be a number >= 0", "--measurement",
                         field="measurement")
    return MeasurementItem(name, kind, value / 100.0)
