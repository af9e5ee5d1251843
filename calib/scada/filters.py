"""Filters of 10-minute SCADA records: each one a flag per record, every flag counted.

:func:`apply_filters` runs the filters of :class:`FilterSettings` on :class:`~calib.scada.reader.ScadaRecords`
and returns a :class:`FilterReport`: the flags (with those set while reading, ``missing`` and
``duplicate_stamp``), their counts overall and per turbine, and the records no flag touched. A
record may carry several flags; each count is the records with that flag, ``removed`` those with
any. The filters:

- ``out_of_range``: a mean outside its range (:attr:`FilterSettings.ranges`);
- ``frozen``: a signal repeating the same value in ``frozen_count`` or more consecutive records of
  a turbine (a stuck sensor or a logger repeating its last value), as OpenOA's
  ``filters.unresponsive_flag``;
- ``start_stop``: at a wind speed in the operating window, the power's minimum (its mean where the
  export gives no minimum) below ``stop_power``, or the rotor speed's minimum at or below
  ``stop_rotor_speed``: the turbine stopped, started or idled during the period;
- ``curtailment``: at a wind speed in the operating window, the pitch above the fine pitch by more
  than ``pitch_margin`` while the power is at most ``curtailment_fraction`` of rated: a pitch-regulated turbine pitches out below rated
  power only when derated, curtailed or stopping;
- ``icing``: temperature below ``icing_temperature`` and power more than ``icing_deficit`` below
  the power curve of the warm records at the same wind speed (bins of the records no other flag
  touched).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.errors import InputError
from calib.scada.bins import bin_index, method_of_bins
from calib.scada.reader import ScadaRecords

#: the filters, in the order they run and are reported
FILTERS = ("out_of_range", "frozen", "start_stop", "curtailment", "icing")


@dataclass(frozen=True)
class FilterSettings:
    """Thresholds of the filters (SI units: m/s, W, deg, rpm, K).

    Parameters
    ----------
    rated_power : float
        Rated power [W].
    ranges : dict
        Signal -> (lower, upper) of its 10-minute mean [SI]; a value outside is ``out_of_range``.
        Default: wind speed 0..40 m/s, power −5 %..110 % of rated.
    frozen_signals : tuple of str
        Signals checked for repeated identical means (those the export has). Default the wind
        speed only: pitch at fine pitch, power at zero and a temperature at 0.1 K resolution
        repeat legitimately.
    frozen_count : int
        Records in a row with one value that make a run frozen (OpenOA's default 3).
    operating_window : (float, float)
        Wind speeds [m/s] at which the turbine should run (start/stop flag).
    stop_power : float or None
        Power [W] below which a record in the window counts as stopped (None: 1 % of rated).
    stop_rotor_speed : float
        Rotor-speed minimum [rpm] at or below which a record counts as stopped (when given).
    fine_pitch : float or None
        Pitch below rated [deg]; None: the median pitch of the records between 20 % and 80 % of rated.
    pitch_margin : float
        Degrees above the fine pitch that count as pitched out.
    curtailment_fraction : float
        Fraction of rated power below which pitching out is curtailment.
    icing_temperature : float
        Temperature [K] below which icing is possible (3 °C).
    icing_deficit : float
        Fraction of the warm power curve a cold record must fall short of to be flagged.
    enabled : tuple of str
        The filters to run (a subset of :data:`FILTERS`).
    """

    rated_power: float
    ranges: dict = field(default_factory=dict)
    frozen_signals: tuple = ("wind_speed",)
    frozen_count: int = 3
    operating_window: tuple = (5.0, 25.0)
    stop_power: float | None = None
    stop_rotor_speed: float = 0.5
    fine_pitch: float | None = None
    pitch_margin: float = 3.0
    curtailment_fraction: float = 0.9
    icing_temperature: float = 276.15
    icing_deficit: float = 0.25
    enabled: tuple = FILTERS

    def __post_init__(self):
        unknown = [f for f in self.enabled if f not in FILTERS]
        if unknown:
            raise InputError(f"unknown filter(s) {', '.join(unknown)}; filters: {', '.join(FILTERS)}",
                             "FilterSettings", field="enabled")
        if not self.rated_power > 0:
            raise InputError(f"rated_power must be > 0 [W], got {self.rated_power!r}", "FilterSettings",
                             field="rated_power")
        if int(self.frozen_count) < 2:
            raise InputError("frozen_count must be >= 2", "FilterSettings", field="frozen_count")

    def range_of(self, signal: str):
        default = {"wind_speed": (0.0, 40.0), "power": (-0.05 * self.rated_power, 1.1 * self.rated_power)}
        return {**default, **self.ranges}.get(signal)


@dataclass(frozen=True)
class FilterReport:
    """Flags per record and their counts.

    Attributes
    ----------
    flags : dict
        Flag name -> bool ndarray (n_records,), reader flags first, then :data:`FILTERS` run.
    kept : ndarray of bool
        Records without any flag.
    counts : dict
        Flag name -> records flagged; ``removed`` and ``kept`` too.
    counts_by_turbine : dict
        Turbine -> the same counts for its records.
    gaps : dict
        Turbine -> missing periods (from the reader).
    fine_pitch : float
        The fine pitch [deg] the curtailment filter used (NaN: not run).
    not_run : dict
        Filter asked for but not run -> why (a signal the export lacks).
    """

    flags: dict
    kept: np.ndarray
    counts: dict
    counts_by_turbine: dict
    gaps: dict
    fine_pitch: float
    not_run: dict = field(default_factory=dict)

    def summary(self) -> str:
        """One line per flag: records flagged (overlaps allowed), then removed and kept."""
        n = self.kept.size
        rows = [f"  {name:<16} {c:>8d}  {100 * c / max(n, 1):5.1f} %" for name, c in self.counts.items()
                if name not in ("removed", "kept")]
        rows += [f"  {'removed (any)':<16} {self.counts['removed']:>8d}  {100 * self.counts['removed'] / max(n, 1):5.1f} %",
                 f"  {'kept':<16} {self.counts['kept']:>8d}  of {n} records; "
                 f"{sum(self.gaps.values())} periods missing (gaps)"]
        rows += [f"  {name:<16} not run: {why}" for name, why in self.not_run.items()]
        return "\n".join(rows)


def frozen_runs(values: np.ndarray, count: int) -> np.ndarray:
    """Flag every value in a run of ``count`` or more identical consecutive values (NaN never equal).

    Parameters
    ----------
    values : ndarray (n,)
        One turbine's series in time order.
    count : int

    Returns
    -------
    ndarray of bool (n,)
    """
    v = np.asarray(values, float)
    flag = np.zeros(v.size, bool)
    if v.size < count:
        return flag
    same = np.concatenate([[False], v[1:] == v[:-1]])
    start = 0
    for i in range(1, v.size + 1):
        if i == v.size or not same[i]:
            if i - start >= count:
                flag[start:i] = True
            start = i
    return flag


def _per_turbine(records: ScadaRecords, skip: np.ndarray, fn) -> np.ndarray:
    """``fn(indices)`` -> bool array over each turbine's records not in ``skip``, in time order."""
    out = np.zeros(len(records), bool)
    for name in records.turbines:
        idx = np.flatnonzero((records.turbine == name) & ~skip)
        out[idx] = fn(idx)
    return out


def estimate_fine_pitch(records: ScadaRecords, rated_power: float) -> float:
    """Median pitch [deg] of the records between 20 % and 80 % of rated power."""
    p, pitch = records.get("power"), records.get("pitch")
    mid = (p > 0.2 * rated_power) & (p < 0.8 * rated_power) & np.isfinite(pitch)
    if not mid.any():
        raise InputError("no record between 20 % and 80 % of rated power to estimate the fine pitch from; give "
                         "FilterSettings(fine_pitch=...)", records.source, field="fine_pitch")
    return float(np.median(pitch[mid]))


def out_of_range_flag(records: ScadaRecords, settings: FilterSettings) -> np.ndarray:
    """A mean outside its range (:meth:`FilterSettings.range_of`)."""
    f = np.zeros(len(records), bool)
    for (signal, stat), v in records.values.items():
        rng = settings.range_of(signal) if stat == "mean" else None
        if rng is not None:
            f |= np.isfinite(v) & ((v < rng[0]) | (v > rng[1]))
    return f


def frozen_flag(records: ScadaRecords, settings: FilterSettings) -> np.ndarray:
    """:func:`frozen_runs` of each of ``frozen_signals`` per turbine, duplicate stamps left out of the series."""
    f = np.zeros(len(records), bool)
    dup = records.flags.get("duplicate_stamp", np.zeros(len(records), bool))
    for signal in settings.frozen_signals:
        if records.has(signal):
            v = records.get(signal)
            f |= _per_turbine(records, dup, lambda idx: frozen_runs(v[idx], int(settings.frozen_count)))
    return f


def _in_window(records: ScadaRecords, settings: FilterSettings) -> np.ndarray:
    ws = records.get("wind_speed")
    return (ws >= settings.operating_window[0]) & (ws <= settings.operating_window[1])


def start_stop_flag(records: ScadaRecords, settings: FilterSettings) -> np.ndarray:
    """In the operating window, the power's minimum (else its mean) below ``stop_power`` or the rotor
    speed's minimum at or below ``stop_rotor_speed``."""
    window = _in_window(records, settings)
    p_low = records.get("power", "min") if records.has("power", "min") else records.get("power")
    stop = 0.01 * settings.rated_power if settings.stop_power is None else settings.stop_power
    f = window & (p_low < stop)
    if records.has("rotor_speed", "min"):
        f |= window & (records.get("rotor_speed", "min") <= settings.stop_rotor_speed)
    return f


def curtailment_flag(records: ScadaRecords, settings: FilterSettings, fine_pitch: float) -> np.ndarray:
    """In the operating window, pitch above ``fine_pitch + pitch_margin`` at power at most
    ``curtailment_fraction`` of rated."""
    return _in_window(records, settings) & (records.get("power") <= settings.curtailment_fraction *
                                            settings.rated_power) & \
        (records.get("pitch") > fine_pitch + settings.pitch_margin)


def icing_flag(records: ScadaRecords, settings: FilterSettings, clean: np.ndarray) -> np.ndarray:
    """Cold (below ``icing_temperature``) and more than ``icing_deficit`` below the power curve of the
    ``clean`` warm records at the same wind speed (where that curve is above 5 % of rated)."""
    ws, p, t = records.get("wind_speed"), records.get("power"), records.get("temperature")
    warm = clean & (t >= settings.icing_temperature)
    if warm.sum() < 3:
        return np.zeros(len(records), bool)
    curve = method_of_bins(ws[warm], p[warm])
    k = bin_index(ws, curve)
    ref = np.where(k >= 0, curve.power[np.clip(k, 0, None)], np.nan)
    return (t < settings.icing_temperature) & (ref > 0.05 * settings.rated_power) & \
        (p < (1.0 - settings.icing_deficit) * ref)


def apply_filters(records: ScadaRecords, settings: FilterSettings) -> FilterReport:
    """Run the filters of ``settings`` on ``records`` (see the module docstring).

    Parameters
    ----------
    records : ScadaRecords
    settings : FilterSettings

    Returns
    -------
    FilterReport
    """
    flags = {k: v.copy() for k, v in records.flags.items()}
    fine = np.nan
    not_run = {name: f"no {signal} mean in the export" for name, signal in (("curtailment", "pitch"),
               ("icing", "temperature")) if name in settings.enabled and not records.has(signal)}
    with np.errstate(invalid="ignore"):
        if "out_of_range" in settings.enabled:
            flags["out_of_range"] = out_of_range_flag(records, settings)
        if "frozen" in settings.enabled:
            flags["frozen"] = frozen_flag(records, settings)
        if "start_stop" in settings.enabled:
            flags["start_stop"] = start_stop_flag(records, settings)
        if "curtailment" in settings.enabled and records.has("pitch"):
            fine = settings.fine_pitch if settings.fine_pitch is not None else \
                estimate_fine_pitch(records, settings.rated_power)
            flags["curtailment"] = curtailment_flag(records, settings, fine)
        if "icing" in settings.enabled and records.has("temperature"):
            flags["icing"] = icing_flag(records, settings, ~np.any(list(flags.values()), axis=0))
    kept = ~np.any(list(flags.values()), axis=0)

    def counts_of(mask):
        c = {name: int(np.sum(f & mask)) for name, f in flags.items()}
        c["removed"] = int(np.sum(~kept & mask))
        c["kept"] = int(np.sum(kept & mask))
        return c

    return FilterReport(flags, kept, counts_of(np.ones(len(records), bool)),
                        {name: counts_of(records.turbine == name) for name in records.turbines},
                        dict(records.gaps), float(fine), not_run)
