"""Measurement uncertainty items a user states (IEC 61400-12-1 category B style), per bin.

Each item is a relative standard uncertainty of one quantity, turned into a power uncertainty
per bin with its sensitivity coefficient (IEC 61400-12-1, Annex D/E):

- ``wind`` (anemometer calibration, mounting, flow distortion): u_P = |dP/dV| · u_V, u_V = r · V;
- ``density`` (air-density measurement): the standard normalizes the wind speed of a
  pitch-regulated turbine by (ρ/ρ₀)^{1/3}, so u_V = r/3 · V and u_P = |dP/dV| · u_V;
- ``power`` (power transducer, current and voltage transformers): u_P = r · P.

Items are independent of each other (added in quadrature within a bin). Across the bins the
standard combines them by category (IEC 61400-12-1:2005, Annex E, eq. E.3 for the AEP): a
category B item (a calibration, a transducer class: the same error in every bin) fully correlated,
added linearly over the bins, u_AEP,k = N_h Σ_i f_i u_k,i; a category A item (statistical: the
scatter of a bin's own data, independent from bin to bin) uncorrelated, in quadrature,
u_AEP,k² = N_h² Σ_i f_i² u_k,i². :func:`aep_uncertainty` does both with the AEP's weights c_i
(:func:`calib.powercurve.aep.aep_weights`, c_i = N_h f_i for the standard's step weights) and adds
the items in quadrature, per category and in total.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from calib.errors import InputError

__all__ = ["MEASUREMENT_CATEGORIES", "MEASUREMENT_KINDS", "MeasurementItem", "aep_uncertainty", "parse_measurement"]

MEASUREMENT_KINDS = ("wind", "density", "power")
#: IEC 61400-12-1 categories: A (statistical, uncorrelated across bins), B (correlated across bins).
MEASUREMENT_CATEGORIES = ("A", "B")


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
    category : str
        ``"B"`` (default: fully correlated across bins) or ``"A"`` (uncorrelated across bins).
    """

    name: str
    kind: str
    relative: float
    category: str = "B"

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
        return f"{self.name}: {100 * self.relative:g} % {what}, category {self.category}"


def aep_uncertainty(items, wind_speed, power, weights) -> dict:
    """1-σ of the AEP from stated measurement items, combined as IEC 61400-12-1 (Annex E) does.

    Parameters
    ----------
    items : sequence of MeasurementItem
    wind_speed : array_like, shape (n_bins,)
        Bin centres [m/s].
    power : array_like, shape (n_bins,)
        The power curve the items act on [W] (electrical, as measured).
    weights : array_like, shape (n_bins,)
        AEP = weights · power (:func:`calib.powercurve.aep.aep_weights`, in any energy unit per W).

    Returns
    -------
    dict
        ``items``: name -> σ_AEP (category B: Σ c_i u_i; category A: (Σ (c_i u_i)²)^½);
        ``A``, ``B``: each category's items in quadrature; ``total``: all in quadrature [energy unit].
    """
    c = np.asarray(weights, float)
    out, by = {}, {"A": 0.0, "B": 0.0}
    for m in items:
        u = np.nan_to_num(m.power_std(wind_speed, power))
        s = float(np.sqrt(np.sum((c * u) ** 2))) if m.category == "A" else float(abs(c @ u))
        out[m.name] = s
        by[m.category] += s ** 2
    return {"items": out, "A": float(np.sqrt(by["A"])), "B": float(np.sqrt(by["B"])),
            "total": float(np.sqrt(by["A"] + by["B"]))}


def parse_measurement(text: str) -> MeasurementItem:
    """``NAME=KIND:PERCENT[:CATEGORY]`` (``anemometer=wind:2``, ``transducer=power:0.5%:B``,
    ``scatter=power:1:A``) as a :class:`MeasurementItem` (category B unless stated).

    Raises
    ------
    InputError
        Naming ``--measurement``, the valid kinds and categories.
    """
    m = re.fullmatch(r"\s*([^=]+?)\s*=\s*(\w+)\s*:\s*([-+0-9.eE]+)\s*%?\s*(?::\s*(\w+)\s*)?", text or "")
    if not m:
        raise InputError(f"--measurement {text!r}: expected NAME=KIND:PERCENT[:CATEGORY], e.g. anemometer=wind:2 "
                         f"or scatter=power:1:A (kinds: {', '.join(MEASUREMENT_KINDS)}; categories: A, B)",
                         "--measurement", field="measurement")
    name, kind, pct, category = m.group(1), m.group(2), m.group(3), (m.group(4) or "B")
    if category.upper() not in MEASUREMENT_CATEGORIES:
        raise InputError(f"--measurement {text!r}: unknown category {category!r}; valid: A (uncorrelated across "
                         "bins), B (correlated across bins)", "--measurement", field="measurement")
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
    return MeasurementItem(name, kind, value / 100.0, category.upper())
