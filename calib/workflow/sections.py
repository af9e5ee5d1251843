"""The typed sections of a workflow file, each built from its table once, at load.

Every section's keys are a schema of :class:`calib.config.Key` (types, required, choices, value
rules), so a rule runs where the table is read and errors name the file and the key path
(``conditions.tsr``, ``truth.bumps[0].block``, ``stages[1].channels`` ...). A rule that needs
more than one key, or names a sub-key (``noise.relative.power``), runs in the section's
``from_table``. :func:`calib.workflow.schema.load_workflow` assembles the sections into a
:class:`calib.workflow.schema.Workflow`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from calib.calibration.settings import RETAIN_MODES, CalibrationSettings
from calib.config import AUTO_OR_NUM, NUM, Key, check_table, schema_of, settings_from_table
from calib.errors import InputError


def number_list(value) -> str | None:
    """A :class:`Key` check: a non-empty array of finite numbers."""
    if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        return "must be a non-empty array of numbers"
    return None if np.all(np.isfinite(np.asarray(value, float))) else "must be finite numbers"


def positive(value) -> str | None:
    """A :class:`Key` check: a number > 0."""
    return None if value > 0 else "must be > 0"


def _positive_numbers(what: str):
    """A :class:`Key` check: an array of numbers, each > 0 (``what`` names them in the error)."""
    return lambda v: number_list(v) or (None if all(x > 0 for x in v) else f"{what} must be > 0")


def _alpha_nodes(value) -> str | None:
    if isinstance(value, str):
        return None if value == "auto" else "must be an array of angles [deg] or \"auto\""
    return number_list(value)


def _eta_nodes(value) -> str | None:
    return number_list(value) or (None if all(0 < x <= 1 for x in value) else "eta nodes must lie in (0, 1] (r/R)")


def _percentiles(value) -> str | None:
    ok = number_list(value) is None and len(value) == 2 and 0 <= value[0] < value[1] <= 100
    return None if ok else "must be two percentiles 0 <= lo < hi <= 100"


def _eta_range(value) -> str | None:
    ok = number_list(value) is None and len(value) == 2 and value[0] < value[1]
    return None if ok else "must be [lo, hi] with lo < hi (r/R)"


def _channel_names(value) -> str | None:
    ok = value and all(isinstance(c, str) for c in value)
    return None if ok else "channels must be a non-empty array of names"


@dataclass(frozen=True)
class Fluid:
    """``[fluid]``: density [kg/m³] and kinematic viscosity [m²/s], each > 0 (None: not given)."""

    density: float | None = None
    kinematic_viscosity: float | None = None

    @classmethod
    def from_table(cls, table: dict | None, source: str) -> "Fluid":
        """The checked ``[fluid]`` table (absent: neither given)."""
        return settings_from_table(cls, dict(table or {}), "fluid", source, FLUID_KEYS)


FLUID_KEYS = {"density": Key(NUM, check=positive), "kinematic_viscosity": Key(NUM, check=positive)}


@dataclass(frozen=True)
class GridTable:
    """``[grid]``: the correction grid's nodes and scales (:class:`calib.corrections.CorrectionGrid`).

    Parameters
    ----------
    alpha_nodes_deg : tuple of float or "auto"
        Angle-of-attack nodes [deg]; ``"auto"``: ``n_alpha_nodes`` over the ``alpha_percentiles`` of the
        angles the nominal model reaches.
    eta_nodes : tuple of float
        Span nodes r/R [-], in (0, 1].
    cl_scale, cd_scale, cl_bound, cd_bound, cd_floor : float, optional
        The grid's scales and bounds (None: the grid's default).
    n_alpha_nodes : int
        Number of automatic α nodes (>= 2).
    alpha_percentiles : tuple of float
        Percentiles [%] of the reached angles the automatic nodes span.
    """

    alpha_nodes_deg: tuple | str
    eta_nodes: tuple
    cl_scale: float | None = None
    cd_scale: float | None = None
    cl_bound: float | None = None
    cd_bound: float | None = None
    cd_floor: float | None = None
    n_alpha_nodes: int = 6
    alpha_percentiles: tuple = (5.0, 95.0)

    @property
    def auto(self) -> bool:
        """Whether the α nodes are placed on the data (``alpha_nodes_deg = "auto"``)."""
        return isinstance(self.alpha_nodes_deg, str)

    def scales(self) -> dict[str, float]:
        """The scales and bounds given, as :class:`calib.corrections.CorrectionGrid` keywords."""
        return {k: float(getattr(self, k)) for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound", "cd_floor")
                if getattr(self, k) is not None}

    @classmethod
    def from_table(cls, table: dict, source: str) -> "GridTable":
        """The checked ``[grid]`` table."""
        return settings_from_table(cls, table, "grid", source, GRID_KEYS)


GRID_KEYS = {"alpha_nodes_deg": Key((list, str), True, check=_alpha_nodes), "eta_nodes": Key(list, True, check=_eta_nodes),
             **{k: Key(NUM) for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound", "cd_floor")},
             "n_alpha_nodes": Key(int, check=lambda v: None if v >= 2 else "must be >= 2"),
             "alpha_percentiles": Key(list, check=_percentiles)}


@dataclass(frozen=True)
class Conditions:
    """``[conditions]``: the synthetic operating points, every tip-speed ratio [-] at every pitch [deg]
    at ``rotor_speed`` [rpm], with the fluid's ``air_density`` [kg/m³] and a ``yaw`` [deg] (None: the
    workflow's)."""

    tsr: tuple
    pitch: tuple
    rotor_speed: float
    air_density: float | None = None
    yaw: float | None = None

    @classmethod
    def from_table(cls, table: dict, source: str) -> "Conditions":
        """The checked ``[conditions]`` table."""
        return settings_from_table(cls, table, "conditions", source, CONDITIONS_KEYS)


CONDITIONS_KEYS = {"tsr": Key(list, True, check=_positive_numbers("tip-speed ratios")),
                   "pitch": Key(list, True, check=number_list),
                   "rotor_speed": Key(NUM, True, check=lambda v: None if v > 0 else "rotor_speed must be > 0 rpm"),
                   "air_density": Key(NUM, check=positive), "yaw": Key(NUM)}


@dataclass(frozen=True)
class MeasurementsTable:
    """``[measurements]``: the measurement ``file`` (relative to the workflow's folder) and how it is read
    (:func:`calib.measurements.read_measurements`)."""

    file: str
    drop_incomplete_rows: bool = False
    time_series: str | None = None
    average_from: float | None = None

    @classmethod
    def from_table(cls, table: dict, source: str) -> "MeasurementsTable":
        """The checked ``[measurements]`` table."""
        return settings_from_table(cls, table, "measurements", source, MEASUREMENTS_KEYS)


MEASUREMENTS_KEYS = {"file": Key(str, True), "drop_incomplete_rows": Key(bool), "time_series": Key(str),
                     "average_from": Key(NUM)}


@dataclass(frozen=True)
class Bump:
    """One smooth bump of a synthetic truth's correction field (:func:`calib.workflow.truth.smooth_field`).

    Parameters
    ----------
    block : {"lift", "drag"}
        ΔC_L or ΔC_D.
    amplitude : float
        Peak value [-].
    alpha_deg, alpha_width : float
        Centre and width (> 0) of its Gaussian in α [deg].
    eta, eta_width : float
        Centre and width (> 0) of its Gaussian in η = r/R [-].
    eta_range : tuple of float, optional
        ``(lo, hi)``: a smooth box in η instead of the Gaussian, with tanh edges of ``edge_width`` (> 0).
    edge_width : float
    """

    block: str
    amplitude: float
    alpha_deg: float
    alpha_width: float
    eta: float = 0.5
    eta_width: float = 0.2
    eta_range: tuple | None = None
    edge_width: float = 0.03


BUMP_KEYS = {"block": Key(str, True, check=lambda v: None if v in ("lift", "drag")
                          else "block must be 'lift' or 'drag'"),
             "amplitude": Key(NUM, True), "alpha_deg": Key(NUM, True), "alpha_width": Key(NUM, True, check=positive),
             "eta": Key(NUM), "eta_width": Key(NUM, check=positive), "eta_range": Key(list, check=_eta_range),
             "edge_width": Key(NUM, check=positive)}


@dataclass(frozen=True)
class Truth:
    """``[truth]``: the synthetic truth, a smooth field of :class:`Bump` sampled every ``alpha_step_deg``
    [deg] and ``eta_step`` [-], and the true values of nuisance parameters (None: nominal)."""

    bumps: tuple
    pitch_offset: float | None = None
    wind_scale: float | None = None
    alpha_step_deg: float = 1.0
    eta_step: float = 0.025

    def nuisance_values(self) -> dict[str, float]:
        """The true values given, by nuisance parameter name."""
        return {k: getattr(self, k) for k in ("pitch_offset", "wind_scale") if getattr(self, k) is not None}

    @classmethod
    def from_table(cls, table: dict, source: str) -> "Truth":
        """The checked ``[truth]`` table, each bump checked as ``truth.bumps[k]``."""
        check_table(table, TRUTH_KEYS, "truth", source)
        bumps = []
        for k, bump in enumerate(table["bumps"]):
            if not isinstance(bump, dict):
                raise InputError("each truth.bumps entry must be a table", source, field=f"truth.bumps[{k}]")
            bumps.append(settings_from_table(Bump, bump, f"truth.bumps[{k}]", source, BUMP_KEYS))
        return settings_from_table(cls, {**table, "bumps": tuple(bumps)}, "truth", source,
                                   {**TRUTH_KEYS, "bumps": Key(tuple, True)})


TRUTH_KEYS = {"pitch_offset": Key(NUM), "wind_scale": Key(NUM), "alpha_step_deg": Key(NUM, check=positive),
              "eta_step": Key(NUM, check=positive), "bumps": Key(list, True)}


@dataclass(frozen=True)
class Noise:
    """``[noise]``: the synthetic measurements' noise, a fraction >= 0 of each channel's RMS, and the seed."""

    relative: dict
    seed: int = 0

    @classmethod
    def from_table(cls, table: dict, source: str) -> "Noise":
        """The checked ``[noise]`` table (a bad fraction named ``noise.relative.CHANNEL``)."""
        check_table(table, NOISE_KEYS, "noise", source)
        for channel, fraction in table["relative"].items():
            if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not fraction >= 0:
                raise InputError(f"must be a noise fraction >= 0 of the channel's RMS, got {fraction!r}", source,
                                 field=f"noise.relative.{channel}")
        return cls(dict(table["relative"]), table.get("seed", 0))


NOISE_KEYS = {"relative": Key(dict, True), "seed": Key(int)}


@dataclass(frozen=True)
class Stage:
    """One ``[[stages]]`` entry: its ``name``, the ``channels`` it calibrates, and a ``retain`` mode replacing
    ``[calibration] retain`` (None: that one)."""

    name: str
    channels: tuple
    retain: str | None = None


STAGE_KEYS = {"name": Key(str, True), "channels": Key(list, True, check=_channel_names),
              "retain": Key(str, choices=RETAIN_MODES)}


def stages_from_list(stages: list, source: str) -> tuple:
    """The checked ``[[stages]]`` (at least one), each named ``stages[k]`` in errors."""
    if not stages:
        raise InputError("at least one stage is needed", source, field="stages")
    out = []
    for k, stage in enumerate(stages):
        if not isinstance(stage, dict):
            raise InputError("each stages entry must be a table", source, field=f"stages[{k}]")
        out.append(settings_from_table(Stage, stage, f"stages[{k}]", source, STAGE_KEYS))
    return tuple(out)


#: [calibration] keys: every CalibrationSettings field (same name, same default), plus ``force`` and
#: ``strict_units``.
CALIBRATION_KEYS = {**schema_of(CalibrationSettings, exclude=("verbose",),
                                overrides={"sigma_bar": AUTO_OR_NUM, "sigma": dict, "relative_sigma": dict,
                                           "condition_sigma": dict, "condition_relative_sigma": dict,
                                           "prior_std": dict, "cd_min": NUM, "max_retained": int,
                                           "band_eta": list}),
                    "force": Key(bool), "strict_units": Key(bool)}


@dataclass(frozen=True)
class CalibrationSection:
    """``[calibration]``: the validated :class:`CalibrationSettings`, and what the unit check does.

    Parameters
    ----------
    settings : CalibrationSettings
        Validated (:meth:`CalibrationSettings.validate`) when the section is built.
    force : bool
        Calibrate even when the unit check finds a unit factor that explains the data.
    strict_units : bool
        Also stop on a misfit no unit factor explains.
    given : frozenset of str
        The keys the table gave (where a setting came from, for the set-up statement).
    """

    settings: CalibrationSettings
    force: bool = False
    strict_units: bool = False
    given: frozenset = frozenset()

    @classmethod
    def from_table(cls, table: dict | None, source: str) -> "CalibrationSection":
        """The checked ``[calibration]`` table (absent: the defaults); errors name ``calibration.KEY``."""
        table = dict(table or {})
        settings = settings_from_table(CalibrationSettings, table, "calibration", source, CALIBRATION_KEYS)
        return cls(settings.validate(source, "calibration."), table.get("force", False),
                   table.get("strict_units", False), frozenset(table))

    def with_noise(self, noise: str, source: str) -> "CalibrationSection":
        """The section with ``noise`` in place of its noise model (``--noise``), validated again."""
        settings = dataclasses.replace(self.settings, noise=noise).validate(source, "calibration.")
        return dataclasses.replace(self, settings=settings, given=self.given | {"noise"})
