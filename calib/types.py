"""Ground-floor vocabulary shared by every layer: statuses, parameters, channels,
operating conditions and evaluations.

Nothing here imports from the rest of the package except :mod:`calib.errors`, so
``bem/``, ``corrections``, ``parametrizations/``, ``models/`` and the calibrator can all
import it without an import running back up (docs/theory.md, Architecture).
"""


from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from calib.errors import InputError


class Status(enum.IntEnum):
    """Per-point outcome of a solve or simulation."""

    CONVERGED = 0
    NOT_CONVERGED = 1
    INVALID_INPUT = 2
    SIMULATION_FAILED = 3
    TIMEOUT = 4
    NOT_STEADY = 5


class ParameterKind(str, enum.Enum):
    """What a parameter stands for; decides its defaults in verdicts and reports."""

    LIFT_CORRECTION = "lift_correction"
    DRAG_CORRECTION = "drag_correction"
    NUISANCE = "nuisance"
    TUNING = "tuning"
    EFFECT = "effect"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Parameter:
    """A scalar model parameter.

    Parameters
    ----------
    name : str
        Unique name, e.g. ``"dCL[alpha=8,eta=0.5]"`` or ``"pitch_offset"``.
    nominal : float
        Value of the nominal (uncalibrated) model, in ``unit``.
    lower, upper : float
        Bounds.
    scale : float
        Typical magnitude of a meaningful change (used to scale the SVD).
    unit : str
    kind : ParameterKind or str
        ``"lift_correction"``, ``"drag_correction"``, ``"nuisance"``, ``"tuning"`` or
        ``"effect"`` (a string is converted; anything else is refused).
    alpha_deg, eta : float
        For correction nodes: the node location on the (α, η) plane [deg], [-]; NaN otherwise.
    description : str
    prior_std : float
        1-σ of the Gaussian prior on the parameter, in ``unit`` (what is believed before the
        data: e.g. 2 deg for a pitch-offset). NaN: the calibration's ``prior_sigma`` × ``scale``.
    """

    name: str
    nominal: float
    lower: float
    upper: float
    scale: float
    unit: str = "-"
    kind: ParameterKind = ParameterKind.TUNING
    alpha_deg: float = float("nan")
    eta: float = float("nan")
    description: str = ""
    prior_std: float = float("nan")

    def __post_init__(self):
        if not (np.isnan(self.prior_std) or self.prior_std > 0):
            raise InputError(f"prior_std must be > 0 or NaN, got {self.prior_std!r}", f"parameter {self.name!r}",
                             field="prior_std")
        try:
            object.__setattr__(self, "kind", ParameterKind(self.kind))
        except ValueError:
            raise InputError(f"unknown kind {self.kind!r}; valid: {', '.join(k.value for k in ParameterKind)}",
                             f"parameter {self.name!r}", field="kind") from None
        if not (self.lower <= self.nominal <= self.upper):
            raise InputError(f"nominal {self.nominal!r} outside its bounds [{self.lower!r}, {self.upper!r}]",
                             f"parameter {self.name!r}", field="nominal")


@dataclass(frozen=True)
class Channel:
    """A named model output with its unit (SI)."""

    name: str
    unit: str
    description: str = ""


CONDITION_FIELDS = ("wind_speed", "rotor_speed", "pitch", "air_density", "yaw")
STANDARD_AIR_DENSITY = 1.225
"""Air density of the ISA at sea level, 15 °C [kg/m^3]: the default of every condition table."""
CONDITION_DEFAULTS = {"air_density": STANDARD_AIR_DENSITY, "yaw": 0.0}
"""The operating conditions a table may leave out, and their values then [kg/m^3], [deg]."""


@dataclass(frozen=True, eq=False)
class OperatingConditions:
    """A batch of steady operating conditions.

    Parameters
    ----------
    wind_speed : array_like, shape (n_points,)
        Hub-height free-stream wind speed [m/s].
    rotor_speed : array_like, shape (n_points,)
        Rotor speed [rpm].
    pitch : array_like, shape (n_points,)
        Collective blade pitch [deg], positive toward feather.
    air_density : array_like or float
        [kg/m^3], default 1.225.
    yaw : array_like or float
        Yaw misalignment [deg], default 0.
    """

    wind_speed: np.ndarray
    rotor_speed: np.ndarray
    pitch: np.ndarray
    air_density: np.ndarray | float = STANDARD_AIR_DENSITY
    yaw: np.ndarray | float = 0.0

    def __post_init__(self):
        ws = np.atleast_1d(np.asarray(self.wind_speed, dtype=float))
        n = ws.size
        for name in CONDITION_FIELDS:
            value = getattr(self, name)
            try:
                a = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                raise InputError(f"expected numbers, got {value!r}", "OperatingConditions", field=name) from None
            a = np.broadcast_to(a, (n,)).copy() if a.ndim == 0 or a.size == 1 else a.reshape(-1)
            if a.shape != (n,):
                raise InputError(f"has {a.size} values, expected {n}", "OperatingConditions", field=name)
            object.__setattr__(self, name, a)

    def __len__(self) -> int:
        return int(self.wind_speed.size)

    @property
    def n_points(self) -> int:
        return len(self)

    def subset(self, index) -> "OperatingConditions":
        """The conditions at ``index`` (any numpy index)."""
        return OperatingConditions(*(getattr(self, f)[index] for f in CONDITION_FIELDS))

    def as_dict(self) -> dict[str, np.ndarray]:
        return {f: getattr(self, f) for f in CONDITION_FIELDS}

    def tip_speed_ratio(self, radius: float) -> np.ndarray:
        """λ = Ω R / V [-] for a rotor of radius ``radius`` [m]."""
        return self.rotor_speed * np.pi / 30.0 * radius / self.wind_speed


class StatusCounts:
    """Mixin for results carrying a per-point ``status`` array."""

    status: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        """True where the point converged."""
        return self.status == Status.CONVERGED

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(~self.ok))


@dataclass(frozen=True, eq=False)
class Evaluation(StatusCounts):
    """Outputs of a forward model over a batch of conditions.

    Attributes
    ----------
    values : ndarray, shape (n_points, n_channels)
        In the units of ``channels``; NaN where ``status != 0``.
    status : ndarray of int, shape (n_points,)
        :class:`Status` codes.
    messages : tuple of str
        One message per point ("" where converged).
    channels : tuple of Channel
    extras : dict
        Model-specific diagnostics (e.g. angles of attack), arrays with first axis n_points.
    """

    values: np.ndarray
    status: np.ndarray
    messages: tuple[str, ...]
    channels: tuple[Channel, ...]
    extras: dict = field(default_factory=dict)

    def channel(self, name: str) -> np.ndarray:
        """Values of one channel, shape (n_points,)."""
        names = [c.name for c in self.channels]
        if name not in names:
            raise KeyError(f"no channel {name!r}; channels are: {', '.join(names)}")
        return self.values[:, names.index(name)]

    def failure_summary(self) -> str:
        """One line: how many points failed and why."""
        if self.n_failed == 0:
            return f"all {self.status.size} points converged"
        kinds = {}
        for s in self.status[~self.ok]:
            kinds[Status(int(s)).name] = kinds.get(Status(int(s)).name, 0) + 1
        detail = ", ".join(f"{k}: {v}" for k, v in sorted(kinds.items()))
        return f"{self.n_failed} of {self.status.size} points failed ({detail})"


def nominal_vector(parameters: Sequence[Parameter]) -> np.ndarray:
    """The nominal parameter vector p₀."""
    return np.array([q.nominal for q in parameters], dtype=float)


def check_parameter_vector(p, parameters: Sequence[Parameter], where: str = "p",
                           check_bounds: bool = True) -> np.ndarray:
    """Validate a parameter vector: right length, finite, inside the bounds. Returns it as floats.

    A value outside [lower, upper] (beyond a round-off margin of 1e-9 × scale) is refused
    rather than evaluated: a model at a pitch offset of 500 deg or a wind scale of 0 gives
    numbers, but not meaningful ones.
    """
    p = np.asarray(p, dtype=float).reshape(-1)
    if p.size != len(parameters):
        raise InputError(f"expected {len(parameters)} parameter values, got {p.size}", where)
    bad = np.flatnonzero(~np.isfinite(p))
    if bad.size:
        raise InputError(f"parameter {parameters[bad[0]].name!r} is not finite ({p[bad[0]]!r})", where)
    if check_bounds:
        lower = np.array([q.lower for q in parameters], float)
        upper = np.array([q.upper for q in parameters], float)
        margin = 1e-9 * np.array([abs(q.scale) for q in parameters], float)
        out = np.flatnonzero((p < lower - margin) | (p > upper + margin))
        if out.size:
            q = parameters[out[0]]
            raise InputError(f"parameter {q.name!r} = {p[out[0]]!r} {q.unit} is outside its bounds "
                             f"[{q.lower!r}, {q.upper!r}]", where, field=q.name)
    return p
