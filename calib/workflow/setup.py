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
from calib.calibration.settings import CalibrationSettings
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.logs import say
from calib.measurements import Measurements, read_measurements, sha256_of
from calib.models.bem_model import BemModel
from calib.models.from_config import (BemModelTable, ExecutorSettings, FmuModelTable, bem_model, bem_setup,
                                      fmu_model)
from calib.rotor.provenance import absolute_table, file_provenance
from calib.rotor.sources import rotor_from_table
from calib.types import STANDARD_AIR_DENSITY, OperatingConditions
from calib.workflow.schema import Workflow
from calib.workflow.sections import Conditions, Fluid, GridTable

log = logging.getLogger("calib.workflow")


# ----------------------------------------------------------------------------- running
@dataclass
class StageOutcome:
    name: str
    result: object
    figures: dict
    out_dir: Path


def synthetic_conditions(conditions: Conditions, rotor, density: float = STANDARD_AIR_DENSITY,
                         yaw: float = 0.0) -> OperatingConditions:
    """The operating points of ``[conditions]``: the product of its tip-speed ratios and pitch angles at its
    rotor speed [rpm], with the fluid's density [kg/m³] and the yaw misalignment [deg] (each replaced by the
    table's where it gives one)."""
    T, P = np.meshgrid(np.asarray(conditions.tsr, float), np.asarray(conditions.pitch, float), indexing="ij")
    rpm = float(conditions.rotor_speed)
    v = rpm * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, rpm), P.ravel(),
                               float(density if conditions.air_density is None else conditions.air_density),
                               float(yaw if conditions.yaw is None else conditions.yaw))


AIR = {"density": STANDARD_AIR_DENSITY, "kinematic_viscosity": AIR_KINEMATIC_VISCOSITY}


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
    model_table: BemModelTable | FmuModelTable
    density: float
    channels: list
    calibration: CalibrationSettings
    force: bool                           # [calibration] force: calibrate whatever the unit check finds
    strict_units: bool                    # [calibration] strict_units: a misfit no unit factor explains stops
    grid_table: GridTable | None
    source: str
    notes: list
    executor: ExecutorSettings
    base_dir: str = "."
    diagnosis: tuple | None = None        # (DiagnosisSettings, channels or None) of [diagnosis]
    validation: object = None             # calib.workflow.validation.ValidationSettings of [validation]
    rotor_files: dict | None = None       # provenance of the rotor files read (calib.rotor.provenance.file_provenance)
    origins: dict = dataclasses.field(default_factory=dict)   # set-up key -> where its value came from

    @property
    def is_fmu(self) -> bool:
        """Whether the model is an FMU (``[model] kind = "fmu"``)."""
        return isinstance(self.model_table, FmuModelTable)

    @property
    def nuisance(self) -> tuple:
        """The native BEM's nuisance parameters (of the truth model too when the model is an FMU)."""
        return BemModelTable().nuisance if self.is_fmu else self.model_table.nuisance

    @property
    def yaw(self) -> float:
        """The yaw misalignment [deg] of points without a yaw column (``[model] yaw``)."""
        return 0.0 if self.is_fmu else self.model_table.yaw

    def model(self, grid: CorrectionGrid, channels, executor=None, effects=()):
        """The forward model of a stage: the native BEM (with ``effects``, e.g. those a
        ``[diagnosis]`` named), or the FMU of ``[model] kind = "fmu"``."""
        if not self.is_fmu:
            return bem_model(self.model_table, self.rotor, self.settings, grid, channels, self.rotor_spec,
                             effects=effects, rotor_files=self.rotor_files)
        return fmu_model(self.model_table, self.rotor_spec, channels, self.source, self.base_dir, grid=grid,
                         executor=executor)

    @property
    def uses_grid(self) -> bool:
        """Whether ``[grid]`` defines the model's correction field (the BEM, a bundled FMU variant)."""
        return not self.is_fmu or self.model_table.variant is not None

    def model_name(self) -> str:
        """The model in words: 'rotor NAME' (native BEM) or 'FMU FILE' / 'FMU variant A'."""
        if not self.is_fmu:
            return f"rotor {self.rotor.name}"
        if self.model_table.variant is not None:
            return f"FMU variant {self.model_table.variant} (rotor {self.rotor.name})"
        return f"FMU {Path(self.model_table.fmu).name}"

    def model_units(self) -> str | None:
        """Where the user set the model's output units: an FMU's mapping file (None for the BEM)."""
        if not self.is_fmu:
            return None
        if self.model_table.mapping is not None:
            return f"the mapping file {Path(self.base_dir) / self.model_table.mapping}"
        return f"the bundled variant {self.model_table.variant}'s mapping file"

    def grid(self, conditions: OperatingConditions, progress: bool = False,
             prefix: str = "[calib run]") -> CorrectionGrid:
        """The correction grid; ``alpha_nodes_deg = "auto"`` places the α nodes over the angles of
        attack the nominal model reaches at ``conditions`` (loaded stations, converged points), and
        says where under the command's ``prefix``. None for an FMU given as a file: its correction
        nodes, if any, come from its mapping."""
        if not self.uses_grid:
            return None
        g, src = self.grid_table, self.source
        eta = np.asarray(g.eta_nodes, float)
        if g.auto:
            lo_q, hi_q = (float(q) for q in g.alpha_percentiles)
            ev = BemModel(self.rotor, None, ("power",), self.settings, ()).evaluate(np.zeros(0), conditions)
            # only stations inside the η node range (outside it the field ramps to zero)
            a = np.asarray(ev.extras["alpha_deg"], float)[ev.ok][:, np.asarray(ev.extras["eta"]) >= eta[0]]
            a = a[np.isfinite(a)]
            if a.size == 0:
                raise InputError("no converged operating point to place the alpha nodes on", src,
                                 field="grid.alpha_nodes_deg")
            lo, hi = np.percentile(a, [lo_q, hi_q])
            alpha = np.round(np.linspace(lo, hi, g.n_alpha_nodes), 2)
            self.notes.append(f"alpha nodes from the data ({lo_q:g}th-{hi_q:g}th percentile of the nominal "
                              f"model's angles of attack): {', '.join(f'{x:g}' for x in alpha)} deg")
            say(log, f"{prefix} set-up: {self.notes[-1]}", progress)
        else:
            alpha = np.asarray(g.alpha_nodes_deg, float)
        try:
            return CorrectionGrid(alpha, eta, **g.scales())
        except InputError as exc:
            raise InputError(exc.message, src, field=f"grid.{exc.field}") from None


def prepare(workflow: Workflow) -> WorkflowSetup:
    """Resolve a loaded workflow's rotor, model, fluid and grid (its tables were checked by
    :func:`calib.workflow.schema.load_workflow`).

    Raises
    ------
    InputError
        Naming the workflow file and the full key (``model.n_sectors``, ``stages.channels``,
        ``grid.cl_scale`` ...): what needs the rotor files or the model to check.
    """
    src, base_dir = workflow.source, workflow.base_dir
    notes = []
    rsrc = rotor_from_table(workflow.rotor, src, base_dir) if workflow.rotor is not None else None
    if workflow.is_fmu and workflow.truth is not None:
        notes.append("synthetic measurements come from the native BEM; the FMU is calibrated to them")
    density, viscosity, fluid_origins = _fluid(workflow.fluid, rsrc)
    if rsrc is None:
        rotor, settings, origins = None, BemSettings(kinematic_viscosity=viscosity), {}
    else:     # an FMU's synthetic measurements: the native BEM of [rotor] with the defaults of [model]
        bem_table = BemModelTable() if workflow.is_fmu else workflow.model
        rotor, settings, origins = bem_setup(bem_table, rsrc, src, viscosity, notes)
    channels = []
    for stage in workflow.stages:
        channels += [c for c in stage.channels if c not in channels]
    _check_channels(workflow.model, rotor, settings, channels, src, base_dir)
    cal = workflow.calibration
    rotor_spec = absolute_table(workflow.rotor, base_dir) if workflow.rotor is not None else None
    setup = WorkflowSetup(rotor, rotor_spec, settings, workflow.model, density, channels, cal.settings, cal.force,
                          cal.strict_units, workflow.grid, src, notes, workflow.executor, base_dir,
                          workflow.diagnosis, workflow.validation, origins={**origins, **fluid_origins})
    _check_grid(setup, workflow)
    if rsrc is not None and rsrc.files:
        setup.rotor_files = file_provenance(rsrc.files, base_dir)
    return setup


def _fluid(fluid: Fluid, rsrc) -> tuple[float, float, dict]:
    """The fluid's density [kg/m³] and kinematic viscosity [m²/s]: from ``[fluid]``, else the rotor
    files, else air at 15 °C; and where each came from."""
    stated = {"density": None if rsrc is None else rsrc.air_density,
              "kinematic_viscosity": None if rsrc is None else rsrc.kinematic_viscosity}
    values, origins = {}, {}
    for key, value in stated.items():
        given = getattr(fluid, key)
        origins[key] = f"[fluid] {key}" if given is not None else "rotor files" if value else "default (air at 15 °C)"
        values[key] = float(given if given is not None else value or AIR[key])
    return values["density"], values["kinematic_viscosity"], origins


def _check_grid(setup: WorkflowSetup, workflow: Workflow) -> None:
    """Validate an explicit ``[grid]`` now; for an FMU given as a file, note what it does not use."""
    g, notes = setup.grid_table, setup.notes
    if setup.is_fmu and not setup.uses_grid:
        if g is not None:
            notes.append("[grid] is not used: the FMU's correction nodes, if any, come from its mapping file")
        if setup.rotor is not None and workflow.measurements is not None:
            notes.append("[rotor] is not used by the FMU (it carries its own rotor); only stated")
    elif not g.auto:
        setup.grid(OperatingConditions([1.0], [1.0], [0.0]))  # validate the explicit grid now


def _check_channels(table, rotor, settings: BemSettings, channels: list, src: str, base_dir) -> None:
    """Refuse a stage channel the configured model does not provide, before any data is read.

    The native BEM is asked directly; an FMU given as a file is opened through its mapping (a
    bundled variant is checked when it is built).
    """
    try:
        if isinstance(table, BemModelTable):
            BemModel(rotor, None, channels, settings, ())
        elif table.variant is None:
            fmu_model(table, None, channels, src, base_dir).close()
    except InputError as exc:
        if exc.field not in ("channels", "outputs"):     # not about a channel: the error as the model gave it
            raise
        raise InputError(exc.message, src, field="stages.channels") from None


def measurements_of(workflow: Workflow, channels) -> "Measurements":
    """The measurement table of ``[measurements]`` (CSV, or OpenFAST output with ``time_series``)."""
    table = workflow.measurements
    path = Path(workflow.base_dir) / table.file
    if not path.is_file():
        raise InputError(f"measurement file not found: {path} (paths in a workflow are relative to the workflow "
                         f"file's folder, {workflow.base_dir})", workflow.source, field="measurements.file")
    try:
        return read_measurements(path, channels, drop_incomplete_rows=table.drop_incomplete_rows,
                                 time_series=table.time_series, average_from=table.average_from)
    except InputError as exc:
        if exc.field in ("time_series", "average_from"):     # a setting: name the workflow key
            raise InputError(exc.message, workflow.source, field=f"measurements.{exc.field}") from None
        raise


def run_inputs(workflow: Workflow) -> dict:
    """What a run's results depend on, for its history manifest: {label: SHA-256 or value}.

    The workflow file's bytes, and the measurement file's when there is one (files named
    by the rotor table are covered by the model identities of the history's records).
    """
    inputs = {"workflow file": sha256_of(workflow.source)}
    if workflow.measurements is not None:
        file = Path(workflow.base_dir) / workflow.measurements.file
        inputs["measurement file"] = sha256_of(str(file)) if file.is_file() else None
    return inputs
