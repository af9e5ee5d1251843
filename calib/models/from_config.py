"""Forward models and executors from workflow tables (``[model]``, ``[executor]``).

``[model]`` with ``kind = "fmu"``::

    [model]
    kind = "fmu"
    fmu = "turbine.fmu"          # or: variant = "A" | "B" (bundled FMU, built on demand
    mapping = "turbine.toml"     #      for the workflow's rotor and grid; mapping optional)
    parameters = ["pitch_offset_blade1"]     # optional: mapped scalar parameters to calibrate
    corrections = true                       # optional: calibrate the correction field
    switches = { tower_shadow = false }      # optional: effect switches (package terms)
    settings = { shaft_tilt = 0.0 }          # optional: [settings] values (package units)
    steady = { settle_revolutions = 4 }      # optional: overrides of the mapping's [steady]
    jacobian = { relative_step = 0.01 }      # optional: overrides of the mapping's [jacobian]
    timeout = 60.0                           # optional: per-simulation timeout [s]
    isolate = true                           # optional: simulate in worker processes

``kind = "bem"`` (the default) takes the keys of a workflow's native-BEM ``[model]``
(:data:`BEM_KEYS`: every :class:`calib.bem.BemSettings` field but the fluid's viscosity, the rotor's
``tilt`` and ``precone`` [deg] and the ``nuisance`` parameters).

``[executor]``::

    [executor]
    kind = "process"      # "serial" (default) | "process" | "dask"
    workers = 2           # optional
    address = "tcp://scheduler:8786"   # dask only: join a running cluster (default: LocalCluster)

Relative paths are relative to ``base_dir`` (the workflow's folder). Unknown keys and
wrong types are refused with the file and the key named.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from calib.bem.solver import BemSettings
from calib.config import NUM, Key, check_table, field_values, names_list, schema_of, settings_from_table
from calib.errors import InputError
from calib.fmu.plan import DEFAULT_TIMEOUT
from calib.models.bem_model import DEFAULT_NUISANCE, NUISANCE, BemModel
from calib.models.registry import model_kind
from calib.types import OperatingConditions

#: [model] keys a rotor file may set (AeroDyn TipLoss/HubLoss/AIDrag/TIDrag/TanInd, InflowWind PLExp):
#: [model] key -> the :class:`calib.rotor.sources.RotorSource` attribute.
FILE_SETUP = {"tip_loss": "tip_loss", "hub_loss": "hub_loss", "drag_in_axial_induction": "drag_in_axial_induction",
              "drag_in_tangential_induction": "drag_in_tangential_induction", "wake_rotation": "tangential_induction",
              "shear_exponent": "shear_exponent"}


@dataclass(frozen=True)
class FmuModelTable:
    """A ``[model] kind = "fmu"`` table (the module docstring shows one), checked.

    Parameters
    ----------
    kind : str
        ``"fmu"``.
    fmu, variant : str, optional
        The FMU file, or the bundled variant (``"A"`` or ``"B"``) to build for the workflow's rotor; one of the two.
    mapping : str, optional
        The mapping file (required with ``fmu``; a variant has its own).
    parameters : tuple of str, optional
        Mapped scalar parameters to calibrate (default: every one the mapping declares).
    corrections : bool
        Calibrate the correction field.
    switches, settings, steady, jacobian : dict, optional
        Effect switches, ``[settings]`` values (package units), and overrides of the mapping's
        ``[steady]`` and ``[jacobian]``.
    timeout : float
        Per-simulation timeout [s].
    isolate : bool
        Simulate in worker processes.
    """

    kind: str = "fmu"
    fmu: str | None = None
    variant: str | None = None
    mapping: str | None = None
    parameters: tuple | None = None
    corrections: bool = True
    switches: dict | None = None
    settings: dict | None = None
    steady: dict | None = None
    jacobian: dict | None = None
    timeout: float = DEFAULT_TIMEOUT
    isolate: bool = True

    @classmethod
    def from_table(cls, table: dict, source: str) -> "FmuModelTable":
        """The checked table (:data:`FMU_KEYS`): exactly one of ``fmu`` and ``variant``; ``mapping`` with ``fmu``.

        Raises
        ------
        InputError
            Naming ``source`` and the key (``model.fmu``, ``model.mapping`` ...).
        """
        t = settings_from_table(cls, table, "model", source, FMU_KEYS, table_label="[model]")
        if (t.fmu is None) == (t.variant is None):
            raise InputError("[model] kind = \"fmu\" needs either fmu = \"PATH\" or variant = \"A\" | \"B\"", source,
                             field="model.fmu")
        if t.fmu is not None and t.mapping is None:
            raise InputError("[model] kind = \"fmu\" with fmu = ... needs mapping = \"PATH\" (the mapping file "
                             "that tells calib how to reach the FMU's variables)", source, field="model.mapping")
        return t


@dataclass(frozen=True)
class BemModelTable:
    """A ``[model] kind = "bem"`` table (:data:`BEM_KEYS`), checked.

    Parameters
    ----------
    options : dict
        The :class:`calib.bem.BemSettings` keywords the table gives, as the fields hold them.
    tilt, precone : float, optional
        Overrides of the rotor's shaft tilt and precone [deg], each within ±30°.
    yaw : float
        The workflow's yaw misalignment [deg], within ±90° (a condition of its points).
    nuisance : tuple of str
        The nuisance parameters (:data:`calib.models.bem_model.NUISANCE`); default
        :data:`calib.models.bem_model.DEFAULT_NUISANCE`.
    given : frozenset of str
        The keys the table gave (where a setting came from, for the set-up statement).
    """

    options: dict = dataclasses.field(default_factory=dict)
    tilt: float | None = None
    precone: float | None = None
    yaw: float = 0.0
    nuisance: tuple = DEFAULT_NUISANCE
    given: frozenset = frozenset()

    @classmethod
    def from_table(cls, table: dict, source: str) -> "BemModelTable":
        """The checked ``[model]`` table of the native BEM (errors name ``source`` and ``model.KEY``)."""
        check_table(table, BEM_KEYS, "model", source)
        angles = {k: float(table[k]) for k in ("tilt", "precone") if k in table}
        return cls(field_values(BemSettings, table), yaw=float(table.get("yaw", 0.0)),
                   nuisance=tuple(table.get("nuisance", DEFAULT_NUISANCE)), given=frozenset(table), **angles)


@dataclass(frozen=True)
class ExecutorSettings:
    """An ``[executor]`` table: ``kind`` (:data:`calib.executors.registry.EXECUTORS`), ``workers``
    (processes, >= 1) and ``address`` (a Dask scheduler; ``kind = "dask"`` only)."""

    kind: str = "serial"
    workers: int | None = None
    address: str | None = None

    @classmethod
    def from_table(cls, table: dict | None, source: str) -> "ExecutorSettings":
        """The checked ``[executor]`` table (serial without one).

        Raises
        ------
        InputError
            Unknown key, wrong type, ``address`` without ``kind = "dask"``.
        """
        st = settings_from_table(cls, dict(table or {}), "executor", source, EXECUTOR_KEYS, table_label="[executor]")
        if st.address is not None and st.kind != "dask":
            raise InputError("'executor.address' applies to kind = \"dask\" only", source, field="executor.address")
        return st


def _angle_within(limit: float):
    """A :class:`calib.config.Key` check: an angle [deg] within ±``limit``."""
    return lambda v: None if -limit <= v <= limit else f"must be an angle in degrees within ±{limit:g}"


def _nuisance_names(value) -> str | None:
    """A :class:`calib.config.Key` check: names of :data:`calib.models.bem_model.NUISANCE`."""
    if names_list(value):
        return names_list(value)
    unknown = [v for v in value if v not in NUISANCE]
    return f"must name nuisance parameters ({', '.join(NUISANCE)}); {unknown[0]!r} is not one" if unknown else None


FMU_KEYS = schema_of(FmuModelTable, overrides={
    "fmu": str, "variant": str, "mapping": str, "switches": dict, "settings": dict, "steady": dict, "jacobian": dict,
    "parameters": Key(list, check=names_list)})
"""[model] keys of an FMU: the :class:`FmuModelTable` fields."""
#: [model] keys of the native BEM: every BemSettings field (same name, same default) except the fluid's
#: viscosity (in [fluid]), plus rotor overrides, the workflow's yaw and the nuisance list.
BEM_KEYS = {**schema_of(BemSettings, exclude=("kinematic_viscosity",),
                        overrides={"n_sectors": int, "polar_smoothing": list}),
            "kind": Key(str), "tilt": Key(NUM, check=_angle_within(30.0)),
            "precone": Key(NUM, check=_angle_within(30.0)),
            "yaw": Key(NUM, check=lambda v: None if -90.0 < v < 90.0 else
                       "must be a yaw misalignment in degrees within ±90"),
            "nuisance": Key(list, check=_nuisance_names)}
EXECUTOR_KEYS = schema_of(ExecutorSettings, overrides={
    "workers": Key(int, check=lambda v: None if v >= 1 else "must be >= 1"), "address": str})
"""[executor] keys: the :class:`ExecutorSettings` fields."""


#: What a "not found" message adds: where relative paths start.
_RELATIVE = " (paths in a workflow are relative to the workflow file's folder)"


def _path(value: str, base_dir) -> Path:
    p = Path(value)
    return p if p.is_absolute() or base_dir is None else Path(base_dir) / p


def model_table(table: dict | None, source: str) -> BemModelTable | FmuModelTable:
    """The checked ``[model]`` table of either kind (an empty or missing one: the native BEM's defaults)."""
    table = dict(table or {})
    if model_kind(table.get("kind", "bem"), source, "model.kind") == "fmu":
        return FmuModelTable.from_table(table, source)
    return BemModelTable.from_table(table, source)


def model_from_workflow(cfg_model: dict, rotor_table: dict, channels, source: str, base_dir=None, *,
                        grid=None, executor=None):
    """The ForwardModel of a workflow's ``[model]`` table (:func:`model_table`, then :func:`build_model`).

    Parameters
    ----------
    cfg_model : dict
        The ``[model]`` table (may be empty: native BEM with defaults).
    rotor_table : dict
        The ``[rotor]`` table (for the native BEM, and for building a bundled variant).
    channels : sequence of str
        Channels the stage calibrates.
    source : str
        The workflow file (named in errors).
    base_dir : str or Path, optional
        Folder that relative paths are relative to.
    grid : CorrectionGrid, optional
        The workflow's correction grid: the native BEM's parameters, and the grid a bundled
        variant is built with (an FMU file carries its own grid in its mapping).
    executor : Executor, optional
        Where FMU simulations run (:func:`executor_of`); default serial.

    Returns
    -------
    BemModel or FmuModel
    """
    table = model_table(cfg_model, source)
    if isinstance(table, BemModelTable):
        if "yaw" in table.given:
            raise InputError("the yaw misalignment is a condition of a workflow's points (calib run), not of a model "
                             "built alone", source, field="model.yaw")
        from calib.rotor.sources import rotor_from_table

        rotor, settings, _ = bem_setup(table, rotor_from_table(dict(rotor_table), source, base_dir), source)
        return bem_model(table, rotor, settings, grid, channels, dict(rotor_table))
    return fmu_model(table, rotor_table, channels, source, base_dir, grid=grid, executor=executor)


def fmu_model(t: FmuModelTable, rotor_table: dict | None, channels, source: str, base_dir=None, *, grid=None,
              executor=None):
    """The :class:`calib.fmu.model.FmuModel` of a checked FMU ``[model]`` table (arguments as
    :func:`model_from_workflow`); a bundled variant is built for ``rotor_table`` and ``grid`` first."""
    from calib.fmu.model import FmuModel

    build = None
    if t.variant is not None:
        from calib.fmu.build import mapping_path
        from calib.fmu.bundled import build_variant
        from calib.rotor.provenance import absolute_table

        build = {"variant": t.variant.upper(), "rotor": absolute_table(rotor_table or {}, base_dir),
                 "grid": grid.to_dict() if grid is not None else None}
        fmu = build_variant(build, source, base_dir)
        mapping = _path(t.mapping, base_dir) if t.mapping is not None else mapping_path(build["variant"])
    else:
        fmu = _path(t.fmu, base_dir)
        mapping = _path(t.mapping, base_dir)
        if not fmu.is_file():
            raise InputError(f"FMU file not found: {fmu}{_RELATIVE}", source, field="model.fmu")
    if not Path(mapping).is_file():
        raise InputError(f"mapping file not found: {mapping}{_RELATIVE}", source, field="model.mapping")
    from calib.fmu.base_runs import shared_by

    # the models of a run share their executor, and the base runs it simulated (the unit check's serve a stage)
    return FmuModel(fmu, mapping, list(channels), parameters=None if t.parameters is None else list(t.parameters),
                    corrections=t.corrections, switches=t.switches, settings=t.settings, steady=t.steady,
                    jacobian=t.jacobian, executor=executor, timeout=t.timeout, isolate=t.isolate, build=build,
                    base_runs=shared_by(executor) if executor is not None else None)


def bem_setup(table: BemModelTable, rsrc, source: str, viscosity: float | None = None,
              notes: list | None = None) -> tuple[object, BemSettings, dict]:
    """The rotor and :class:`calib.bem.BemSettings` of the native BEM of a checked ``[model]`` table.

    Each BEM option comes from the table if given, else from the rotor files if they state it
    (:data:`FILE_SETUP`), else from the settings' default; ``tilt`` and ``precone`` [deg] override the
    rotor's.

    Parameters
    ----------
    table : BemModelTable
    rsrc : calib.rotor.sources.RotorSource
        The rotor of ``[rotor]`` and what its files state.
    source : str
        The file named in errors.
    viscosity : float, optional
        The fluid's kinematic viscosity [m²/s] (default: the settings' default, air at 15 °C).
    notes : list of str, optional
        A line per value taken from the files or overridden is appended.

    Returns
    -------
    rotor : calib.rotor.geometry.Rotor
    settings : BemSettings
        Checked on the rotor (its azimuth sectors).
    origins : dict
        ``{key: "rotor files"}`` for each option taken from the files.

    Raises
    ------
    InputError
        A setting the BEM refuses, named ``model.KEY``.
    """
    notes = [] if notes is None else notes
    rotor = angle_overrides(table, rsrc.rotor, notes)
    kwargs, origins = dict(table.options), {}
    for key, attr in FILE_SETUP.items():
        file_value = getattr(rsrc, attr)
        if key not in kwargs and file_value is not None:
            kwargs[key] = file_value
            origins[key] = "rotor files"
            notes.append(f"{key} = {file_value} from the rotor files")
    if viscosity is not None:
        kwargs["kinematic_viscosity"] = viscosity
    try:
        settings = BemSettings(**kwargs)
        settings.sectors_for(rotor, OperatingConditions([1.0], [1.0], [0.0]))
    except InputError as exc:
        raise InputError(exc.message, source, field=f"model.{exc.field}") from None
    return rotor, settings, origins


def bem_model(table: BemModelTable, rotor, settings: BemSettings, grid, channels, rotor_source: dict | None,
              effects=(), rotor_files: dict | None = None) -> BemModel:
    """The native BEM of a checked ``[model]`` table on ``rotor`` with ``settings`` (:func:`bem_setup`): the
    one builder of a workflow's, a ``calib diagnose --config``'s and :func:`model_from_workflow`'s."""
    return BemModel(rotor, grid, list(channels), settings, table.nuisance, rotor_source=rotor_source,
                    effects=effects, rotor_files=rotor_files)


def angle_overrides(table: BemModelTable, rotor, notes: list | None = None):
    """``rotor`` with the ``tilt`` and ``precone`` of a ``[model]`` table [deg]; a line per override is added
    to ``notes`` when given."""
    overrides = {}
    for key, attr in (("tilt", "tilt_deg"), ("precone", "precone_deg")):
        value = getattr(table, key)
        if value is not None:
            overrides[attr] = value
            if notes is not None:
                notes.append(f"{key} {value:g} deg from [model] (rotor files: {getattr(rotor, attr):g} deg)")
    return dataclasses.replace(rotor, **overrides) if overrides else rotor


def executor_of(settings: ExecutorSettings, source: str, progress=None):
    """The executor of checked ``[executor]`` settings (:class:`ExecutorSettings`)."""
    from calib.executors import get_executor

    try:
        return get_executor(settings.kind, settings.workers, settings.address, progress, source)
    except InputError as exc:
        raise InputError(exc.message, source, field=f"executor.{exc.field}" if exc.field else "executor") from None


def executor_from_table(table: dict | None, source: str, progress=None):
    """The executor of an ``[executor]`` table (serial without one): :meth:`ExecutorSettings.from_table`,
    then :func:`executor_of`."""
    return executor_of(ExecutorSettings.from_table(table, source), source, progress)
