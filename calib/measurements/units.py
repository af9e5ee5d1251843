"""Column names of a measurement table and their units: the unit table of the measurements.

Every known column name has a physical quantity (:func:`quantity_of`): the operating
conditions, the hub channels, per-blade root moments, spanwise channels ``<q>@<r/R>``,
azimuth harmonics of these and ``<name>_sigma`` of each. Each quantity accepts the units of
:data:`UNITS` (the first is the SI unit of the ForwardModel contract, :func:`si_unit`) and the
further spellings of :data:`UNIT_ALIASES`; :func:`canonical_unit` matches a unit as a file
writes it (``kN-m``, ``KNm``, ``kN·m``). Column names are compared after
:func:`normalize_name`.
"""

from __future__ import annotations

import re

import numpy as np

from calib.types import CONDITION_FIELDS

REQUIRED_CONDITIONS = ("wind_speed", "rotor_speed", "pitch")

#: Accepted units per physical quantity: unit -> factor to SI. The first unit of each
#: quantity is the SI unit of the ForwardModel contract.
UNITS: dict[str, dict[str, float]] = {
    "speed": {"m/s": 1.0, "km/h": 1.0 / 3.6},
    "rotor_speed": {"rpm": 1.0, "rad/s": 30.0 / np.pi},          # SI of the contract is rpm
    "angle": {"deg": 1.0, "rad": 180.0 / np.pi},                  # contract angles are in deg
    "density": {"kg/m^3": 1.0, "kg/m3": 1.0},
    "power": {"W": 1.0, "kW": 1e3, "MW": 1e6},
    "force": {"N": 1.0, "kN": 1e3, "MN": 1e6},
    "moment": {"N m": 1.0, "Nm": 1.0, "kN m": 1e3, "kNm": 1e3, "MN m": 1e6, "MNm": 1e6},
    "coefficient": {"-": 1.0, "1": 1.0},
    "force_per_length": {"N/m": 1.0, "kN/m": 1e3},
}

#: Further spellings, per quantity: key after :func:`_unit_key` -> unit of :data:`UNITS`.
UNIT_ALIASES: dict[str, dict[str, str]] = {
    "speed": {"ms1": "m/s", "kmh": "km/h", "kph": "km/h", "km/hr": "km/h", "kmh1": "km/h"},
    "rotor_speed": {"r/min": "rpm", "1/min": "rpm", "min1": "rpm", "rads1": "rad/s"},
    "angle": {"°": "deg", "degree": "deg", "degrees": "deg", "radian": "rad", "radians": "rad"},
    "density": {"kgm3": "kg/m^3", "kg/m³": "kg/m^3"},
    "power": {},
    "force": {},
    "moment": {},
    "coefficient": {"": "-"},
    "force_per_length": {"nm1": "N/m", "knm1": "kN/m"},
}

#: the quantity of each fixed column name (the others: spanwise and per-blade patterns)
FIXED_QUANTITY = {
    "wind_speed": "speed", "rotor_speed": "rotor_speed", "pitch": "angle", "yaw": "angle",
    "air_density": "density", "power": "power", "thrust": "force", "torque": "moment",
    "root_flap_moment": "moment", "root_edge_moment": "moment", "hub_flap_moment": "moment",
}
_SPANWISE = re.compile(r"^(cn|ct|fn|ft)@([0-9]*\.?[0-9]+)$")


def _unit_key(unit: str) -> str:
    """Spelling-insensitive key of a unit: lower case, without blanks, '·', '*', '-', '.', '^'."""
    u = unit.strip().lower()
    if u in ("-", "1"):
        return u
    for ch in (" ", "·", "*", "-", ".", "^"):
        u = u.replace(ch, "")
    return u.replace("³", "3")


def canonical_unit(quantity: str, unit: str) -> str | None:
    """The :data:`UNITS` spelling of ``unit`` for ``quantity`` (``None`` if not accepted).

    Matching ignores case, blanks and the separators ``·``, ``*``, ``-``, ``.`` and ``^``,
    so ``kN-m`` (OpenFAST), ``KNm`` and ``kN·m`` all give ``kN m``.
    """
    key = _unit_key(unit)
    for u in UNITS[quantity]:
        if _unit_key(u) == key:
            return u
    return UNIT_ALIASES.get(quantity, {}).get(key)


def normalize_name(name: str) -> str:
    """Column name as the loader compares it: lower case, blanks and hyphens as ``_``."""
    n = re.sub(r"[\s\-]+", "_", name.strip().lower())
    return n.strip("_")


_PER_BLADE = re.compile(r"^(root_flap_moment|root_edge_moment)_blade[1-3]$")
# azimuth harmonics of a channel over whole revolutions: amplitude `<channel>_1p` (the channel's
# quantity) and phase `<channel>_1p_phase` (an angle), orders 1, 2, 3 (calib.fmu.model)
_HARMONIC = re.compile(r"^(?P<base>.+)_(?P<order>[123])p(?P<phase>_phase)?$")


def quantity_of(column: str) -> str | None:
    """Physical quantity of a column name (``None`` if unknown).

    Known: the conditions, the hub channels, per-blade root moments
    ``root_flap_moment_blade1`` .. ``_blade3``, spanwise ``<q>@<r/R>``, azimuth harmonics
    of any of these channels (``root_flap_moment_1p`` has the channel's quantity,
    ``root_flap_moment_1p_phase`` is an angle), and ``<name>_sigma`` of each.
    """
    base = column[:-6] if column.endswith("_sigma") else column
    quantity = _channel_quantity(base)
    if quantity is not None:
        return quantity
    h = _HARMONIC.match(base)
    if h and h.group("base") not in CONDITION_FIELDS:
        # a harmonic of a channel, not of a harmonic: no recursion on names like power_1p_1p_1p...
        quantity = _channel_quantity(h.group("base"))
        if quantity is not None:
            return "angle" if h.group("phase") else quantity
    return None


def _channel_quantity(name: str) -> str | None:
    """Quantity of a condition, hub channel, per-blade moment or spanwise channel (no harmonics, no σ)."""
    if name in FIXED_QUANTITY:
        return FIXED_QUANTITY[name]
    if _PER_BLADE.match(name):
        return "moment"
    m = _SPANWISE.match(name)
    if m:
        return "coefficient" if m.group(1) in ("cn", "ct") else "force_per_length"
    return None


def si_unit(quantity: str) -> str:
    """The SI unit of a quantity in the ForwardModel contract (``rpm`` and ``deg`` included)."""
    return next(iter(UNITS[quantity]))


def is_channel_name(name: str) -> bool:
    """True for a known output-channel name (hub loads or spanwise ``q@r/R``)."""
    return name not in CONDITION_FIELDS and quantity_of(name) is not None and not name.endswith("_sigma")
