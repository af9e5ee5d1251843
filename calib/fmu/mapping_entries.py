"""The entries of a mapping file: what each mapped FMI variable is, in calib's terms.

One frozen data class per kind of entry of a :class:`~calib.fmu.mapping.Mapping`. An
:class:`Entry` (an input, and the base of the others) carries the unit conversion of the
mapping file (:mod:`calib.fmu.mapping`), package = sign · (scale · fmu + offset) [mod wrap],
both ways (:meth:`Entry.to_package`, :meth:`Entry.to_fmu`); :class:`OutputEntry`,
:class:`ParameterEntry` and :class:`SettingEntry` add what an output, a calibrated parameter
and a fixed setting need; :class:`SpanwiseOutput`, :class:`Switch` and :class:`Corrections`
are the spanwise stations, the effect switches and the correction nodes. All are built, and
checked, by :func:`calib.fmu.mapping.load_mapping`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.errors import InputError


@dataclass(frozen=True)
class Entry:
    """One mapped FMI variable and its conversion to package units.

    Attributes
    ----------
    name : str
        Package name (``wind_speed``, ``power``, ``pitch_offset_blade1`` ...).
    variable : str
        FMI variable name.
    element : int or None
        0-based element of an FMI 3 array variable.
    scale, offset : float
        package = sign · (scale · fmu + offset).
    sign : int
        ±1.
    wrap : float or None
        Period of the package value (e.g. 360 for an azimuth).
    unit : str
        The FMU's unit (informative).
    """

    name: str
    variable: str
    element: int | None = None
    scale: float = 1.0
    offset: float = 0.0
    sign: int = 1
    wrap: float | None = None
    unit: str = ""
    description: str = ""

    def to_package(self, x):
        """FMU value(s) -> package value(s)."""
        y = self.sign * (self.scale * np.asarray(x, float) + self.offset)
        return np.mod(y, self.wrap) if self.wrap else y

    def to_fmu(self, y):
        """Package value(s) -> FMU value(s)."""
        return (self.sign * np.asarray(y, float) - self.offset) / self.scale


@dataclass(frozen=True)
class OutputEntry(Entry):
    """A mapped output; ``channel_unit`` is its unit in package terms."""

    channel_unit: str = "-"


@dataclass(frozen=True)
class ParameterEntry(Entry):
    """A mapped scalar parameter with what the calibrator needs (package units).

    ``nominal``, ``lower``, ``upper`` are NaN when the file leaves them out; the adapter then
    takes the FMU's start value, min and max (converted). The file itself holds finite numbers.
    """

    kind: str = "tuning"
    nominal: float = float("nan")
    lower: float = float("nan")
    upper: float = float("nan")
    typical: float = 1.0
    prior_std: float = float("nan")
    package_unit: str = ""


@dataclass(frozen=True)
class SettingEntry(Entry):
    """A fixed parameter; ``value`` (package units) is written at instantiation when given."""

    value: float | bool | None = None


@dataclass(frozen=True)
class SpanwiseOutput:
    """Outputs along blade 1 at output stations (scalars or one FMI 3 array)."""

    name: str
    variables: tuple[str, ...] = ()
    variable: str | None = None
    radius_variables: tuple[str, ...] = ()
    radius_variable: str | None = None
    scale: float = 1.0
    offset: float = 0.0
    unit: str = ""


@dataclass(frozen=True)
class Switch:
    """An effect toggle: FMI variable and the values meaning on / off (and named models)."""

    effect: str
    variable: str
    on: float | bool
    off: float | bool
    values: dict = field(default_factory=dict)

    def value(self, setting, source: str = "switches"):
        """FMU value for ``True``/``False`` or a named model (``"snel"``)."""
        if isinstance(setting, str):
            if setting not in self.values:
                raise InputError(f"switch '{self.effect}' has no model {setting!r}; valid: "
                                 f"{', '.join(['on', 'off', *self.values])}", source, field=self.effect)
            return self.values[setting]
        return self.on if setting else self.off


@dataclass(frozen=True)
class Corrections:
    """How the correction field reaches the FMU: node grid and variables per block."""

    layout: str
    lift: str
    drag: str
    scale: float
    grid_file: str | None
    alpha_nodes_deg: tuple | None
    eta_nodes: tuple | None
    grid_options: dict

    def variable_names(self, n_alpha: int, n_eta: int) -> tuple[list[str], list[str]]:
        """FMI names of the lift and drag node variables (scalar layout) or the two arrays."""
        if self.layout == "array":
            return [self.lift], [self.drag]
        names = []
        for template in (self.lift, self.drag):
            names.append([template.format(i=i, j=j) for i in range(n_alpha) for j in range(n_eta)])
        return names[0], names[1]
