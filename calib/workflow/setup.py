"""A loaded workflow made ready to run (:func:`prepare`): rotor, BEM settings with where each came from,
fluid, channels checked against the configured model, calibration settings, the stages' measurements."""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.bem.polar_grid import AIR_KINEMATIC_VISCOSITY
from calib.calibration.calibrator import CalibrationSettings
from calib.config import field_values, settings_from_table
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.logs import say
from calib.measurements import Measurements, read_measurements, sha256_of
from calib.models.bem_model import BemModel
from calib.models.from_config import angle_overrides
from calib.models.registry import model_kind
from calib.rotor.provenance import absolute_table, file_provenance
from calib.rotor.sources import rotor_from_table
from calib.types import STANDARD_AIR_DENSITY, OperatingConditions
from calib.workflow.schema import CALIBRATION_KEYS, number_array

log = logging.getLogger("calib.workflow")


# ----------------------------------------------------------------------------- running
@dataclass
class StageOutcome:
    name: str
    result: object
    figures: dict
    out_dir: Path


def synthetic_conditions(cfg: dict, rotor, src: str, density: float = STANDARD_AIR_DENSITY,
                         yaw: float = 0.0) -> OperatingConditions:
    """The operating points of ``[conditions]``: the product of its tip-speed ratios and pitch angles at its
    rotor speed, with the fluid's density and the yaw misalignment."""
    tsr = number_array(cfg["tsr"], "conditions.tsr", src)
    pitch = number_array(cfg["pitch"], "conditions.pitch", src)
    if np.any(tsr <= 0):
        raise InputError("tip-speed ratios must be > 0", src, field="conditions.tsr")
    T, P = np.meshgrid(tsr, pitch, indexing="ij")
    rpm = float(cfg["rotor_speed"])
    if rpm <= 0:
        raise InputError("rotor_speed must be > 0 rpm", src, field="conditions.rotor_speed")
    v = rpm * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, rpm), P.ravel(), float(cfg.get("air_density", density)),
                               float(cfg.get("yaw", yaw)))


AIR = {"density": STANDARD_AIR_DENSITY, "kinematic_viscosity": AIR_KINEMATIC_VISCOSITY}
#: [model] keys a rotor file may set (AeroDyn TipLoss/HubLoss/AIDrag/TIDrag/TanInd, InflowWind PLExp).
FILE_SETUP = {"tip_loss": "tip_loss", "hub_loss": "hub_loss", "drag_in_axial_induction": "drag_in_axial_induction",
              "drag_in_tangential_induction": "drag_in_tangential_induction", "wake_rotation": "tangential_induction",
              "shear_exponent": "shear_exponent"}


@dataclasses.dataclass
class WorkflowSetup:
    """What a workflow's settings resolve to, before any data is read.

    Each BEM option comes from the ``[model]`` key if given, else from the rotor files
    (AeroDyn, InflowWind, windIO) if they state it, else from :class:`calib.bem.BemSettings`'s
    default; ``notes`` say which came from where.
    """

    rotor: object
    rotor_spec: dict
    settings: BemSettings
    nuisance: tuple
    density: float
    channels: list
    calibration: dict
    calibration_settings: CalibrationSettings
    force: bool
    grid_table: dict
    source: str
    notes: list
    fmu_table: dict | None = None
    executor_table: dict | None = None
    base_dir: str = "."
    yaw: float = 0.0
    diagnosis: tuple | None = None        # (DiagnosisSettings, channels or None) of [diagnosis]
    validation: object = None             # calib.workflow.validation.ValidationSettings of [validation]
    strict_units: bool = False            # [calibration] strict_units: a misfit no unit factor explains stops
    rotor_files: dict | None = None       # provenance of the rotor files read (calib.rotor.provenance.file_provenance)
    origins: dict = dataclasses.field(default_factory=dict)   # set-up key -> where its value came from

    def model(self, grid: CorrectionGrid, channels, executor=None, effects=()):
        """The forward model of a stage: the native BEM (with ``effects``, e.g. those a
        ``[diagnosis]`` named), or the FMU of ``[model] kind = "fmu"``."""
        if self.fmu_table is None:
            return BemModel(self.rotor, grid, channels, self.settings, self.nuisance, rotor_source=self.rotor_spec,
                            effects=effects, rotor_files=self.rotor_files)
        from calib.models.from_config import model_from_workflow
        return model_from_workflow(self.fmu_table, self.rotor_spec, list(channels), self.source, self.base_dir,
                                   grid=grid, executor=executor)

    @property
    def uses_grid(self) -> bool:
        """Whether ``[grid]`` defines the model's correction field (the BEM, a bundled FMU variant)."""
        return self.fmu_table is None or "variant" in self.fmu_table

    def model_name(self) -> str:
        """The model in words: 'rotor NAME' (native BEM) or 'FMU FILE' / 'FMU variant A'."""
        if self.fmu_table is None:
            return f"rotor {self.rotor.name}"
        if "variant" in self.fmu_table:
            return f"FMU variant {self.fmu_table['variant']} (rotor {self.rotor.name})"
        return f"FMU {Path(self.fmu_table['fmu']).name}"

    def model_units(self) -> str | None:
        """Where the user set the model's output units: an FMU's mapping file (None for the BEM)."""
        if self.fmu_table is None:
            return None
        if "mapping" in self.fmu_table:
            return f"the mapping file {Path(self.base_dir) / self.fmu_table['mapping']}"
        return f"the bundled variant {self.fmu_table.get('variant', '?')}'s mapping file"

    def grid(self, conditions: OperatingConditions, progress: bool = False,
             prefix: str = "[calib run]") -> CorrectionGrid:
        """The correction grid; ``alpha_nodes_deg = "auto"`` places the α nodes over the angles of
        attack the nominal model reaches at ``conditions`` (loaded stations, converged points), and
        says where under the command's ``prefix``. None for an FMU given as a file: its correction
        nodes, if any, come from its mapping."""
        if not self.uses_grid:
            return None
        g, src = self.grid_table, self.source
        alpha = g["alpha_nodes_deg"]
        if isinstance(alpha, str):
            n = int(g.get("n_alpha_nodes", 6))
            lo_q, hi_q = (float(q) for q in g.get("alpha_percentiles", [5.0, 95.0]))
            if n < 2:
                raise InputError(f"must be >= 2, got {n}", src, field="grid.n_alpha_nodes")
            if not 0 <= lo_q < hi_q <= 100:
                raise InputError(f"must be two percentiles 0 <= lo < hi <= 100, got {g['alpha_percentiles']!r}",
                                 src, field="grid.alpha_percentiles")
            ev = BemModel(self.rotor, None, ("power",), self.settings, ()).evaluate(np.zeros(0), conditions)
            eta_nodes = number_array(g["eta_nodes"], "grid.eta_nodes", src)
            # only stations inside the η node range (outside it the field ramps to zero)
            reach = eta_nodes[0]
            a = np.asarray(ev.extras["alpha_deg"], float)[ev.ok][:, np.asarray(ev.extras["eta"]) >= reach]
            a = a[np.isfinite(a)]
            if a.size == 0:
                raise InputError("no converged operating point to place the alpha nodes on", src,
                                 field="grid.alpha_nodes_deg")
            lo, hi = np.percentile(a, [lo_q, hi_q])
            alpha = np.round(np.linspace(lo, hi, n), 2)
            self.notes.append(f"alpha nodes from the data ({lo_q:g}th-{hi_q:g}th percentile of the nominal "
                              f"model's angles of attack): {', '.join(f'{x:g}' for x in alpha)} deg")
            say(log, f"{prefix} set-up: {self.notes[-1]}", progress)
        else:
            alpha = number_array(alpha, "grid.alpha_nodes_deg", src)
        eta = number_array(g["eta_nodes"], "grid.eta_nodes", src)
        if np.any((eta <= 0) | (eta > 1)):
            raise InputError(f"eta nodes must lie in (0, 1] (r/R), got {g['eta_nodes']!r}", src,
                             field="grid.eta_nodes")
        try:
            return CorrectionGrid(alpha, eta, **{k: float(g[k]) for k in ("cl_scale", "cd_scale", "cl_bound",
                                                                          "cd_bound", "cd_floor") if k in g})
        except InputError as exc:
            raise InputError(exc.message, src, field=f"grid.{exc.field}") from None


def prepare(cfg: dict) -> WorkflowSetup:
    """Resolve a loaded workflow's rotor, model, fluid, grid and calibration settings.

    Raises
    ------
    InputError
        Naming the workflow file and the full key (``model.tilt``, ``calibration.noise``,
        ``grid.eta_nodes`` ...).
    """
    src = cfg["_source"]
    notes = []
    rsrc = rotor_from_table(cfg["rotor"], src, cfg["_dir"]) if "rotor" in cfg else None
    rotor = rsrc.rotor if rsrc is not None else None
    fmu_table, mcfg = _model_kind(cfg, src, notes)
    rotor = angle_overrides(mcfg, rotor, src, notes)
    for key in ("tilt", "precone"):
        mcfg.pop(key, None)
    nuisance = tuple(mcfg.pop("nuisance", ["pitch_offset"]))
    yaw = float(mcfg.pop("yaw", 0.0))
    if not -90.0 < yaw < 90.0:
        raise InputError(f"must be a yaw misalignment in degrees within ±90, got {yaw!r}", src, field="model.yaw")
    kwargs, origins = _bem_options(mcfg, rsrc, notes)
    density, viscosity = _fluid(cfg, rsrc, src, origins)
    settings = _bem_settings(kwargs, viscosity, rotor, nuisance, src)
    channels = _stage_channels(cfg, src)
    _check_channels(fmu_table, rotor, settings, channels, src, cfg["_dir"])
    calib_cfg = dict(cfg.get("calibration", {}))
    force = bool(calib_cfg.pop("force", False))
    strict_units = bool(calib_cfg.pop("strict_units", False))
    cal = settings_from_table(CalibrationSettings, calib_cfg, "calibration", src, CALIBRATION_KEYS
                              ).validate(src, "calibration.")
    g = cfg.get("grid")
    if g is not None and isinstance(g["alpha_nodes_deg"], str) and g["alpha_nodes_deg"] != "auto":
        raise InputError(f"must be an array of angles [deg] or \"auto\", got {g['alpha_nodes_deg']!r}", src,
                         field="grid.alpha_nodes_deg")
    rotor_spec = absolute_table(cfg["rotor"], cfg["_dir"]) if "rotor" in cfg else None
    setup = WorkflowSetup(rotor, rotor_spec, settings, nuisance, density,
                          channels, calib_cfg, cal, force, g, src, notes, fmu_table, cfg.get("executor"),
                          cfg["_dir"], yaw)
    _check_grid(setup, cfg)
    _add_diagnosis_and_validation(setup, cfg)
    setup.strict_units = strict_units
    setup.origins = origins
    if rsrc is not None and rsrc.files:
        setup.rotor_files = file_provenance(rsrc.files, cfg["_dir"])
    return setup


def _model_kind(cfg: dict, src: str, notes: list) -> tuple[dict | None, dict]:
    """The FMU table of ``[model] kind = "fmu"`` (None for the native BEM) and the ``[model]``
    keys left for the native BEM (none for an FMU)."""
    mcfg = dict(cfg.get("model", {}))
    kind = model_kind(mcfg.pop("kind", "bem"), src, "model.kind")
    fmu_table = None
    if kind == "fmu":
        fmu_table, mcfg = {"kind": "fmu", **mcfg}, {}
        if "measurements" not in cfg:
            notes.append("synthetic measurements come from the native BEM; the FMU is calibrated to them")
    return fmu_table, mcfg


def _bem_options(mcfg: dict, rsrc, notes: list) -> tuple[dict, dict]:
    """The :class:`calib.bem.BemSettings` keywords of the remaining ``[model]`` keys, completed by
    what the rotor files state (:data:`FILE_SETUP`), and the origin of those taken from the files."""
    kwargs = field_values(BemSettings, mcfg)      # (the keys are checked by the workflow's schema)
    origins = {}
    for key, attr in FILE_SETUP.items() if rsrc is not None else ():
        file_value = getattr(rsrc, attr)
        if key not in kwargs and file_value is not None:
            kwargs[key] = file_value
            origins[key] = "rotor files"
            notes.append(f"{key} = {file_value} from the rotor files")
    return kwargs, origins


def _fluid(cfg: dict, rsrc, src: str, origins: dict) -> tuple[float, float]:
    """The fluid's density [kg/m³] and kinematic viscosity [m²/s]: from ``[fluid]``, else the rotor
    files, else air at 15 °C; where each came from is added to ``origins``."""
    fluid = dict(cfg.get("fluid", {}))
    stated = {"density": None if rsrc is None else rsrc.air_density,
              "kinematic_viscosity": None if rsrc is None else rsrc.kinematic_viscosity}
    for key, value in stated.items():
        origins[key] = f"[fluid] {key}" if key in fluid else "rotor files" if value else "default (air at 15 °C)"
    density = float(fluid.get("density", stated["density"] or AIR["density"]))
    viscosity = float(fluid.get("kinematic_viscosity", stated["kinematic_viscosity"] or AIR["kinematic_viscosity"]))
    for key, value in (("density", density), ("kinematic_viscosity", viscosity)):
        if not value > 0:
            raise InputError(f"must be > 0, got {value!r}", src, field=f"fluid.{key}")
    return density, viscosity


def _bem_settings(kwargs: dict, viscosity: float, rotor, nuisance: tuple, src: str) -> BemSettings:
    """The BEM settings (checked on ``rotor`` when there is one), with the kinematic viscosity
    [m²/s]; the nuisance parameters' names checked."""
    try:
        settings = BemSettings(kinematic_viscosity=viscosity, **kwargs)
        if rotor is not None:
            settings.sectors_for(rotor, OperatingConditions([1.0], [1.0], [0.0]))
    except InputError as exc:
        raise InputError(exc.message, src, field=f"model.{exc.field}") from None
    from calib.models.bem_model import NUISANCE
    for name in nuisance:
        if name not in NUISANCE:
            raise InputError(f"unknown nuisance parameter {name!r}; valid: {', '.join(NUISANCE)}", src,
                             field="model.nuisance")
    return settings


def _stage_channels(cfg: dict, src: str) -> list:
    """Every stage's channels, each once, in the order they first appear."""
    channels = []
    for k, s in enumerate(cfg["stages"]):
        if not s["channels"] or not all(isinstance(c, str) for c in s["channels"]):
            raise InputError("channels must be a non-empty array of names", src, field=f"stages[{k}].channels")
        channels += [c for c in s["channels"] if c not in channels]
    return channels


def _check_grid(setup: WorkflowSetup, cfg: dict) -> None:
    """Validate an explicit ``[grid]`` now; for an FMU given as a file, note what it does not use."""
    g, notes = setup.grid_table, setup.notes
    if setup.fmu_table is not None and not setup.uses_grid:
        if g is not None:
            notes.append("[grid] is not used: the FMU's correction nodes, if any, come from its mapping file")
        if setup.rotor is not None and "measurements" in cfg:
            notes.append("[rotor] is not used by the FMU (it carries its own rotor); only stated")
    elif not isinstance(g["alpha_nodes_deg"], str):
        setup.grid(OperatingConditions([1.0], [1.0], [0.0]))  # validate the explicit grid now


def _add_diagnosis_and_validation(setup: WorkflowSetup, cfg: dict) -> None:
    """The settings of ``[diagnosis]`` (native BEM with measured data only) and ``[validation]``."""
    from calib.diagnosis.in_workflow import diagnosis_settings
    from calib.workflow.validation import ValidationSettings
    src = setup.source
    if "diagnosis" in cfg:
        if setup.fmu_table is not None:
            raise InputError("a workflow's [diagnosis] runs on the native BEM only; remove [diagnosis], use "
                             "[model] kind = \"bem\", or diagnose the FMU with calib diagnose --config (its "
                             "[model] kind = \"fmu\")", src, field="diagnosis")
        if "measurements" not in cfg:
            raise InputError("[diagnosis] needs measured data ([measurements] file = ...)", src, field="diagnosis")
        setup.diagnosis = diagnosis_settings(cfg["diagnosis"], src)
    if "validation" in cfg:
        setup.validation = ValidationSettings.from_table(cfg["validation"], src)


def _check_channels(fmu_table: dict | None, rotor, settings: BemSettings, channels: list, src: str,
                    base_dir) -> None:
    """Refuse a stage channel the configured model does not provide, before any data is read.

    The native BEM is asked directly; an FMU given as a file is opened through its mapping (a
    bundled variant is checked when it is built).
    """
    try:
        if fmu_table is None:
            BemModel(rotor, None, channels, settings, ())
        elif "variant" not in fmu_table:
            from calib.models.from_config import model_from_workflow
            model_from_workflow(fmu_table, None, channels, src, base_dir).close()
    except InputError as exc:
        if exc.field not in ("channels", "outputs"):     # not about a channel: the error as the model gave it
            raise
        raise InputError(exc.message, src, field="stages.channels") from None


def measurements_of(cfg: dict, channels) -> "Measurements":
    """The measurement table of ``[measurements]`` (CSV, or OpenFAST output with ``time_series``)."""
    table = cfg["measurements"]
    path = Path(cfg["_dir"]) / table["file"]
    if not path.is_file():
        raise InputError(f"measurement file not found: {path} (paths in a workflow are relative to the workflow "
                         f"file's folder, {cfg['_dir']})", cfg["_source"], field="measurements.file")
    try:
        return read_measurements(Path(cfg["_dir"]) / table["file"], channels,
                                 drop_incomplete_rows=table.get("drop_incomplete_rows", False),
                                 time_series=table.get("time_series"), average_from=table.get("average_from"))
    except InputError as exc:
        if exc.field in ("time_series", "average_from"):     # a setting: name the workflow key
            raise InputError(exc.message, cfg["_source"], field=f"measurements.{exc.field}") from None
        raise


def run_inputs(cfg: dict) -> dict:
    """What a run's results depend on, for its history manifest: {label: SHA-256 or value}.

    The workflow file's bytes, and the measurement file's when there is one (files named
    by the rotor table are covered by the model identities of the history's records).
    """
    inputs = {"workflow file": sha256_of(cfg["_source"])}
    if "measurements" in cfg:
        file = Path(cfg["_dir"]) / cfg["measurements"]["file"]
        inputs["measurement file"] = sha256_of(str(file)) if file.is_file() else None
    return inputs


