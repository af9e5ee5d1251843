"""SCADA signals, their units and the column names of common exports that map onto them.

A SCADA export holds, per 10-minute record, statistics of signals: ``Ws_avg`` (mean wind speed),
``Ws_std``, ``P_min`` ... :data:`SIGNALS` lists the signals calib knows, with the physical
quantity, the accepted units (factor and offset to SI) and the range a 10-minute mean may take in
SI (a value outside it in the column's median says the unit is wrong). :data:`COLUMN_MAP` maps
export column names (compared after :func:`calib.measurements.units.normalize_name`) to
``(signal, statistic)`` with the unit the export writes when the header gives none; a user extends
it with ``mapping={"MyWind_mean": ("wind_speed", "mean", "m/s")}``.

Statistics: ``mean``, ``std``, ``min``, ``max``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping

from calib.errors import InputError
from calib.measurements.units import normalize_name

STATISTICS = ("mean", "std", "min", "max")


@dataclass(frozen=True)
class Signal:
    """A SCADA signal: its quantity, accepted units and the plausible range of its mean in SI.

    Parameters
    ----------
    quantity : str
        Physical quantity (``speed``, ``power``, ``angle``, ``rotor_speed``, ``temperature``,
        ``pressure``, ``fraction``, ``density``).
    units : dict
        Unit -> (factor, offset): ``SI = value * factor + offset``; the first is the SI unit.
    plausible : (float, float)
        Range [SI] the median of a mean column must lie in; outside it the unit is wrong.
    """

    quantity: str
    units: Mapping[str, tuple[float, float]]
    plausible: tuple[float, float]

    @property
    def si_unit(self) -> str:
        return next(iter(self.units))


_SPEED = {"m/s": (1.0, 0.0), "km/h": (1 / 3.6, 0.0)}
_ANGLE = {"deg": (1.0, 0.0), "rad": (57.29577951308232, 0.0)}
#: the signals calib knows, by name
SIGNALS: dict[str, Signal] = {
    "wind_speed": Signal("speed", _SPEED, (0.0, 40.0)),
    "power": Signal("power", {"W": (1.0, 0.0), "kW": (1e3, 0.0), "MW": (1e6, 0.0)}, (-1e6, 2e7)),
    "pitch": Signal("angle", _ANGLE, (-20.0, 120.0)),
    "rotor_speed": Signal("rotor_speed", {"rpm": (1.0, 0.0), "rad/s": (9.549296585513721, 0.0)}, (0.0, 60.0)),
    "generator_speed": Signal("rotor_speed", {"rpm": (1.0, 0.0), "rad/s": (9.549296585513721, 0.0)},
                              (0.0, 3000.0)),
    "temperature": Signal("temperature", {"K": (1.0, 0.0), "degC": (1.0, 273.15)}, (203.0, 333.0)),
    "pressure": Signal("pressure", {"Pa": (1.0, 0.0), "hPa": (100.0, 0.0), "mbar": (100.0, 0.0),
                                    "kPa": (1e3, 0.0)}, (5.0e4, 1.1e5)),
    "humidity": Signal("fraction", {"-": (1.0, 0.0), "%": (0.01, 0.0)}, (0.0, 1.0)),
    "air_density": Signal("density", {"kg/m^3": (1.0, 0.0)}, (0.8, 1.6)),
    "yaw": Signal("angle", _ANGLE, (-720.0, 720.0)),
    "wind_direction": Signal("angle", _ANGLE, (-720.0, 720.0)),
    "vane": Signal("angle", _ANGLE, (-360.0, 360.0)),
    "torque": Signal("moment", {"N m": (1.0, 0.0), "kN m": (1e3, 0.0)}, (-1e8, 1e8)),
}

#: further spellings of units, after lower-casing and removing blanks
UNIT_SPELLINGS = {"m/s": "m/s", "ms-1": "m/s", "km/h": "km/h", "w": "W", "kw": "kW", "mw": "MW",
                  "deg": "deg", "°": "deg", "degree": "deg", "degrees": "deg", "rad": "rad", "rpm": "rpm",
                  "1/min": "rpm", "rad/s": "rad/s", "k": "K", "kelvin": "K", "degc": "degC", "deg_c": "degC",
                  "°c": "degC", "c": "degC", "celsius": "degC", "pa": "Pa", "hpa": "hPa", "mbar": "mbar",
                  "kpa": "kPa", "-": "-", "1": "-", "%": "%", "percent": "%", "kg/m^3": "kg/m^3", "kg/m3": "kg/m^3",
                  "kg/m³": "kg/m^3", "nm": "N m", "n m": "N m", "knm": "kN m", "kn m": "kN m"}

_SUFFIX = {"avg": "mean", "mean": "mean", "std": "std", "stdev": "std", "min": "min", "max": "max"}
#: short signal names of common exports (Senvion/ENGIE La Haute Borne, many OEM exports), with the
#: unit written when the header gives none
_SHORT = {"ws": ("wind_speed", "m/s"), "p": ("power", "kW"), "ba": ("pitch", "deg"), "rs": ("rotor_speed", "rpm"),
          "ds": ("generator_speed", "rpm"), "ot": ("temperature", "degC"), "pr": ("pressure", "hPa"),
          "rh": ("humidity", "%"), "ya": ("yaw", "deg"), "wa": ("wind_direction", "deg"), "va": ("vane", "deg"),
          "rm": ("torque", "N m")}
_LONG = {"wind_speed": "m/s", "power": "W", "pitch": "deg", "rotor_speed": "rpm", "generator_speed": "rpm",
         "temperature": "degC", "pressure": "hPa", "humidity": "%", "air_density": "kg/m^3"}

#: export column name (normalized) -> (signal, statistic, unit when the header gives none)
COLUMN_MAP: dict[str, tuple[str, str, str]] = {
    **{f"{short}_{suf}": (sig, stat, unit) for short, (sig, unit) in _SHORT.items() for suf, stat in _SUFFIX.items()},
    **{f"{name}_{suf}": (name, stat, unit) for name, unit in _LONG.items() for suf, stat in _SUFFIX.items()},
}

#: columns that are not signals: the time stamp and the turbine
TIME_COLUMNS = ("date_time", "timestamp", "time_stamp", "datetime", "time", "date")
TURBINE_COLUMNS = ("wind_turbine_name", "turbine", "turbine_id", "asset_id", "wtg")


def canonical_unit(signal: str, unit: str) -> str | None:
    """The :data:`SIGNALS` spelling of ``unit`` for ``signal`` (``None`` if that signal does not accept it)."""
    key = re.sub(r"\s+", " ", unit.strip().lower())
    spelled = UNIT_SPELLINGS.get(key, UNIT_SPELLINGS.get(key.replace(" ", ""), unit.strip()))
    return spelled if spelled in SIGNALS[signal].units else None


def column_map(extra: Mapping[str, tuple] | None = None, source: str = "mapping") -> dict[str, tuple[str, str, str]]:
    """:data:`COLUMN_MAP` extended by ``extra`` (name -> (signal, statistic[, unit])), checked.

    Raises
    ------
    InputError
        An unknown signal, statistic or unit in ``extra`` (the key named).
    """
    out = dict(COLUMN_MAP)
    for name, entry in (extra or {}).items():
        entry = tuple(entry)
        if len(entry) not in (2, 3):
            raise InputError(f"a mapping entry is (signal, statistic[, unit]), got {entry!r}", source, field=name)
        signal, stat = entry[0], entry[1]
        if signal not in SIGNALS:
            raise InputError(f"unknown signal {signal!r}; signals: {', '.join(SIGNALS)}", source, field=name)
        if stat not in STATISTICS:
            raise InputError(f"unknown statistic {stat!r}; statistics: {', '.join(STATISTICS)}", source, field=name)
        unit = entry[2] if len(entry) == 3 else SIGNALS[signal].si_unit
        if canonical_unit(signal, unit) is None:
            raise InputError(f"unit {unit!r} is not one of {signal}'s: {', '.join(SIGNALS[signal].units)}", source,
                             field=name)
        out[normalize_name(name)] = (signal, stat, canonical_unit(signal, unit))
    return out
