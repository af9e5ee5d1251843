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

``kind = "bem"`` (the default) takes the native BEM keys ``nuisance``, ``use_tilt``,
``n_sectors``, ``shear_exponent``, ``tip_loss``, ``hub_loss``.

``[executor]``::

    [executor]
    kind = "process"      # "serial" (default) | "process" | "dask"
    workers = 2           # optional
    address = "tcp://scheduler:8786"   # dask only: join a running cluster (default: LocalCluster)

Relative paths are relative to ``base_dir`` (the workflow's folder). Unknown keys and
wrong types are refused with the file and the key named.
"""

from __future__ import annotations

from pathlib import Path

from calib.config import NUM, check_table
from calib.errors import InputError
from calib.models.registry import MODEL_KINDS

FMU_KEYS = {"kind": str, "fmu": str, "variant": str, "mapping": str, "parameters": list, "corrections": bool,
            "switches": dict, "settings": dict, "steady": dict, "jacobian": dict, "timeout": NUM, "isolate": bool}
BEM_KEYS = {"kind": str, "nuisance": list, "use_tilt": bool, "n_sectors": int, "shear_exponent": NUM,
            "tip_loss": bool, "hub_loss": bool}
EXECUTOR_KEYS = {"kind": str, "workers": int, "address": str}


def _check(table, spec: dict, section: str, source: str) -> None:
    check_table(table, spec, section, source, table_label=f"[{section}]")


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
    kind = cfg.get("kind", "bem")
    if kind not in MODEL_KINDS:
        raise InputError(f"unknown model kind {kind!r}; valid kinds: {', '.join(MODEL_KINDS)}", source,
                         field="model.kind")
    if kind == "bem":
        _check(cfg, BEM_KEYS, "model", source)
        from calib.bem import BemSettings
        from calib.models.bem_model import BemModel
        from calib.rotor.sources import rotor_from_table

        rotor = rotor_from_table(dict(rotor_table), source, base_dir).rotor
        settings = BemSettings(use_tilt=cfg.get("use_tilt", False), n_sectors=cfg.get("n_sectors"),
                               shear_exponent=float(cfg.get("shear_exponent", 0.0)),
                               tip_loss=cfg.get("tip_loss", True), hub_loss=cfg.get("hub_loss", True))
        return BemModel(rotor, grid, list(channels), settings, tuple(cfg.get("nuisance", ["pitch_offset"])),
                        rotor_source=dict(rotor_table))
    _check(cfg, FMU_KEYS, "model", source)
    from calib.fmu import plan as fp
    from calib.fmu.model import FmuModel

    if ("fmu" in cfg) == ("variant" in cfg):
        raise InputError("[model] kind = \"fmu\" needs either fmu = \"PATH\" or variant = \"A\" | \"B\"", source,
                         field="model.fmu")
    build = None
    if "variant" in cfg:
        from calib.fmu.build import mapping_path
        from calib.fmu.bundled import build_variant
        from calib.rotor.sources import absolute_table

        build = {"variant": cfg["variant"].upper(), "rotor": absolute_table(rotor_table or {}, base_dir),
                 "grid": grid.to_dict() if grid is not None else None}
        fmu = build_variant(build, source, base_dir)
        mapping = _path(cfg["mapping"], base_dir) if "mapping" in cfg else mapping_path(build["variant"])
    else:
        if "mapping" not in cfg:
            raise InputError("[model] kind = \"fmu\" with fmu = ... needs mapping = \"PATH\" (the mapping file "
                             "that tells calib how to reach the FMU's variables)", source, field="model.mapping")
        fmu = _path(cfg["fmu"], base_dir)
        mapping = _path(cfg["mapping"], base_dir)
        if not fmu.is_file():
            raise InputError(f"FMU file not found: {fmu}", source, field="model.fmu")
    if not Path(mapping).is_file():
        raise InputError(f"mapping file not found: {mapping}", source, field="model.mapping")
    params = cfg.get("parameters")
    if params is not None and not all(isinstance(p, str) for p in params):
        raise InputError("'model.parameters' must be an array of names", source, field="model.parameters")
    return FmuModel(fmu, mapping, list(channels), parameters=params, corrections=cfg.get("corrections", True),
                    switches=cfg.get("switches"), settings=cfg.get("settings"), steady=cfg.get("steady"),
                    jacobian=cfg.get("jacobian"), executor=executor, timeout=float(cfg.get("timeout", fp.DEFAULT_TIMEOUT)),
                    isolate=cfg.get("isolate", True), build=build)


def executor_from_table(table: dict | None, source: str, progress=None):
    """The executor of a workflow's ``[executor]`` table (serial without one).

    Raises
    ------
    InputError
        Unknown key or kind, wrong type, ``address`` without ``kind = "dask"``.
    """
    from calib.executors import get_executor

    table = dict(table or {})
    _check(table, EXECUTOR_KEYS, "executor", source)
    kind = table.get("kind", "serial")
    if "address" in table and kind != "dask":
        raise InputError("'executor.address' applies to kind = \"dask\" only", source, field="executor.address")
    if "workers" in table and table["workers"] < 1:
        raise InputError(f"'executor.workers' must be >= 1, got {table['workers']}", source, field="executor.workers")
    try:
        return get_executor(kind, table.get("workers"), table.get("address"), progress, source)
    except InputError as exc:
        raise InputError(exc.message, source, field=f"executor.{exc.field}" if exc.field else "executor") from None
