"""From records to a power curve: density, normalization, filters and the method of bins in one call.

:func:`power_curve` is the thin layer over the pure functions of :mod:`calib.scada.density`,
:mod:`calib.scada.filters` and :mod:`calib.scada.bins`; a user may call those directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.scada.bins import PowerCurveBins, method_of_bins
from calib.scada.density import RHO_REFERENCE, air_density, normalized_wind_speed
from calib.scada.filters import FilterReport, FilterSettings, apply_filters
from calib.scada.reader import ScadaRecords


@dataclass(frozen=True)
class PowerCurveAnalysis:
    """What :func:`power_curve` did.

    Attributes
    ----------
    report : FilterReport
    bins : PowerCurveBins
        Of the kept records.
    density : ndarray or None
        Air density per record [kg/m^3] (None: neither measured nor computable).
    wind_speed : ndarray
        The wind speed binned per record [m/s] (normalized where ``density`` is known and asked).
    notes : tuple of str
    """

    report: FilterReport
    bins: PowerCurveBins
    density: np.ndarray | None
    wind_speed: np.ndarray
    notes: tuple


def record_density(records: ScadaRecords, pressure: float | None = None) -> tuple[np.ndarray | None, str]:
    """Air density per record [kg/m^3]: measured, or from temperature, pressure (the column, else the
    constant ``pressure`` [Pa]) and humidity (dry air where none) by IEC 61400-12-1."""
    if records.has("air_density"):
        return records.get("air_density"), "air density measured"
    if not records.has("temperature"):
        return None, "no air density: neither density nor temperature in the export"
    if records.has("pressure"):
        b, how = records.get("pressure"), "pressure measured"
    elif pressure is not None:
        b, how = float(pressure), f"pressure {float(pressure):g} Pa given"
    else:
        return None, "no air density: temperature but no pressure (give pressure= [Pa])"
    phi = records.get("humidity") if records.has("humidity") else 0.0
    return air_density(records.get("temperature"), b, phi), \
        f"air density by IEC 61400-12-1 from temperature, {how}, " + \
        ("humidity measured" if records.has("humidity") else "dry air (no humidity)")


def power_curve(records: ScadaRecords, settings: FilterSettings, *, normalize: bool = True,
                reference_density: float = RHO_REFERENCE, pressure: float | None = None,
                width: float = 0.5, align: str = "iec") -> PowerCurveAnalysis:
    """Filter ``records`` and bin the kept ones (IEC 61400-12-1 method of bins).

    Parameters
    ----------
    records : ScadaRecords
    settings : FilterSettings
    normalize : bool
        Normalize the wind speed to ``reference_density`` (pitch-regulated turbine) where the
        density is known.
    reference_density : float
        ρ₀ [kg/m^3].
    pressure : float, optional
        Station pressure [Pa] when the export has none.
    width, align
        As :func:`~calib.scada.bins.method_of_bins`.

    Returns
    -------
    PowerCurveAnalysis
    """
    density, note = record_density(records, pressure)
    notes = [note]
    ws = records.get("wind_speed")
    if normalize and density is not None:
        ws = normalized_wind_speed(ws, density, reference_density)
        notes.append(f"wind speed normalized to {reference_density:g} kg/m^3")
    report = apply_filters(records, settings)
    kept = report.kept
    conditions = {name: records.get(name)[kept] for name in ("pitch", "rotor_speed") if records.has(name)}
    if density is not None:
        conditions["air_density"] = np.broadcast_to(density, ws.shape)[kept]
    within = {name: records.get(name, "std")[kept] for name in ("wind_speed", "pitch", "rotor_speed", "power")
              if records.has(name, "std")}
    bins = method_of_bins(ws[kept], records.get("power")[kept], conditions=conditions, within_std=within,
                          width=width, align=align)
    return PowerCurveAnalysis(report, bins, density, ws, tuple(notes))
