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
from calib.config import NUM, Key, names_list, schema_of, settings_from_table
from calib.errors import InputError
from calib.fmu.plan import DEFAULT_TIMEOUT
from calib.models.registry import model_kind

@dataclass(frozen=True)
class FmuModelTable:
    """A ``[model] kind = "fmu"`` table (the module docstring shows one).

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


@dataclass(frozen=True)
class ExecutorSettings:
    """An ``[executor]`` table: ``kind`` (:data:`calib.executors.registry.EXECUTORS`), ``workers``
    (processes, >= 1) and ``address`` (a Dask scheduler; ``kind = "dask"`` only)."""

    kind: str = "serial"
    workers: int | None = None
    address: str | None = None


FMU_KEYS = schema_of(FmuModelTable, overrides={
    "fmu": str, "variant": str, "mapping": str, "switches": dict, "settings": dict, "steady": dict, "jacobian": dict,
    "parameters": Key(list, check=names_list)})
"""[model] keys of an FMU: the :class:`FmuModelTable` fields."""
#: [model] keys of the native BEM: every BemSettings field (same name, same default) except the fluid's
#: viscosity (in [fluid]), plus rotor overrides, the workflow's yaw and the nuisance list.
BEM_KEYS = {**schema_of(BemSettings, exclude=("kinematic_viscosity",),
                        overrides={"n_sectors": int, "polar_smoothing": list}),
            "kind": (str, False), "tilt": (NUM, False), "precone": (NUM, False), "yaw": (NUM, False),
            "nuisance": (list, False)}
EXECUTOR_KEYS = schema_of(ExecutorSettings, overrides={
    "workers": Key(int, check=lambda v: None if v >= 1 else "must be >= 1"), "address": str})
"""[executor] keys: the :class:`ExecutorSettings` fields."""


#: What a "not found" message adds: where relative paths start.
_RELATIVE = " (paths in a workflow are relative to the workflow file's folder)"


def _path(value: str, base_dir) -> Path:
    p = Path(value)
    return p if p.is_absolute() or base_dir is None else Path(base_dir) / p


def model_from_workflow(cfg_model: dict, rotor_table: dict, channels, source: str, base_dir=None, *,
                        grid=None, executor=None):
    """The ForwardModel of a workflow's ``[model]`` table.

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
        Where FMU simulations run (:func:`executor_from_table`); default serial.

    Returns
    -------
    BemModel or FmuModel
    """
    cfg = dict(cfg_model or {})
    kind = model_kind(cfg.get("kind", "bem"), source, "model.kind")
    if kind == "bem":
        return _bem_model(cfg, rotor_table, grid, channels, source, base_dir)
    t = settings_from_table(FmuModelTable, cfg, "model", source, FMU_KEYS, table_label="[model]")
    from calib.fmu.model import FmuModel

    if (t.fmu is None) == (t.variant is None):
        raise InputError("[model] kind = \"fmu\" needs either fmu = \"PATH\" or variant = \"A\" | \"B\"", source,
                         field="model.fmu")
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
        if t.mapping is None:
            raise InputError("[model] kind = \"fmu\" with fmu = ... needs mapping = \"PATH\" (the mapping file "
                             "that tells calib how to reach the FMU's variables)", source, field="model.mapping")
        fmu = _path(t.fmu, base_dir)
        mapping = _path(t.mapping, base_dir)
        if not fmu.is_file():
            raise InputError(f"FMU file not found: {fmu}{_RELATIVE}", source, field="model.fmu")
    if not Path(mapping).is_file():
        raise InputError(f"mapping file not found: {mapping}{_RELATIVE}", source, field="model.mapping")
    return FmuModel(fmu, mapping, list(channels), parameters=None if t.parameters is None else list(t.parameters),
                    corrections=t.corrections, switches=t.switches, settings=t.settings, steady=t.steady,
                    jacobian=t.jacobian, executor=executor, timeout=t.timeout, isolate=t.isolate, build=build)


def _bem_model(cfg: dict, rotor_table: dict, grid, channels, source: str, base_dir):
    """The native BEM of a ``[model]`` table (:data:`BEM_KEYS`) on the rotor of ``rotor_table``."""
    from calib.models.bem_model import BemModel
    from calib.rotor.sources import rotor_from_table

    settings = settings_from_table(BemSettings, cfg, "model", source, BEM_KEYS)
    if "yaw" in cfg:
        raise InputError("the yaw misalignment is a condition of a workflow's points (calib run), not of a model "
                         "built alone", source, field="model.yaw")
    rotor = angle_overrides(cfg, rotor_from_table(dict(rotor_table), source, base_dir).rotor, source)
    return BemModel(rotor, grid, list(channels), settings, tuple(cfg.get("nuisance", ["pitch_offset"])),
                    rotor_source=dict(rotor_table))


def angle_overrides(cfg: dict, rotor, source: str, notes: list | None = None):
    """``rotor`` with the ``tilt`` and ``precone`` of a ``[model]`` table [deg], each within ±30°;
    a line per override is added to ``notes`` when given."""
    overrides = {}
    for key, attr in (("tilt", "tilt_deg"), ("precone", "precone_deg")):
        if key in cfg:
            value = float(cfg[key])
            if not -30.0 <= value <= 30.0:
                raise InputError(f"must be an angle in degrees within ±30, got {value!r}", source,
                                 field=f"model.{key}")
            overrides[attr] = value
            if notes is not None:
                notes.append(f"{key} {value:g} deg from [model] (rotor files: {getattr(rotor, attr):g} deg)")
    return dataclasses.replace(rotor, **overrides) if overrides else rotor


def executor_from_table(table: dict | None, source: str, progress=None):
    """The executor of a workflow's ``[executor]`` table (serial without one).

    Raises
    ------
    InputError
        Unknown key or kind, wrong type, ``address`` without ``kind = "dask"``.
    """
    from calib.executors import get_executor

    st = settings_from_table(ExecutorSettings, dict(table or {}), "executor", source, EXECUTOR_KEYS,
                             table_label="[executor]")
    if st.address is not None and st.kind != "dask":
        raise InputError("'executor.address' applies to kind = \"dask\" only", source, field="executor.address")
    try:
        return get_executor(st.kind, st.workers, st.address, progress, source)
    except InputError as exc:
        raise InputError(exc.message, source, field=f"executor.{exc.field}" if exc.field else "executor") from None
