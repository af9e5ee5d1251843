"""The workflow file: its schema (one table per section, checked by :mod:`calib.config`) and loading it into
a typed, frozen :class:`Workflow` (its sections in :mod:`calib.workflow.sections`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from calib.config import Key, check_table
from calib.diagnosis.in_workflow import diagnosis_settings
from calib.errors import InputError
from calib.models.from_config import BEM_KEYS, BemModelTable, ExecutorSettings, FmuModelTable, model_table
from calib.tomlfile import read_toml
from calib.workflow.sections import (BUMP_KEYS, CALIBRATION_KEYS, CONDITIONS_KEYS, FLUID_KEYS, GRID_KEYS,
                                     MEASUREMENTS_KEYS, NOISE_KEYS, STAGE_KEYS, TRUTH_KEYS, CalibrationSection,
                                     Conditions, Fluid, GridTable, MeasurementsTable, Noise, Truth, stages_from_list)
from calib.workflow.validation import ValidationSettings

#: [model] keys of the native BEM (:data:`calib.models.from_config.BEM_KEYS`).
MODEL_KEYS = BEM_KEYS

#: schema: section -> key -> :class:`calib.config.Key` (``rotor``: checked by
#: :func:`calib.rotor.sources.rotor_from_table`; an FMU's ``model``: by
#: :meth:`calib.models.from_config.FmuModelTable.from_table`)
SCHEMA = {
    "": {"name": Key(str, True), "description": Key(str), "rotor": Key(dict), "model": Key(dict),
         "fluid": Key(dict), "grid": Key(dict), "conditions": Key(dict), "measurements": Key(dict),
         "truth": Key(dict), "noise": Key(dict), "calibration": Key(dict), "executor": Key(dict),
         "diagnosis": Key(dict), "validation": Key(dict), "stages": Key(list, True)},
    "model": MODEL_KEYS,
    "fluid": FLUID_KEYS,
    "grid": GRID_KEYS,
    "conditions": CONDITIONS_KEYS,
    "measurements": MEASUREMENTS_KEYS,
    "truth": TRUTH_KEYS,
    "truth.bumps": BUMP_KEYS,
    "noise": NOISE_KEYS,
    "calibration": CALIBRATION_KEYS,
    "stages": STAGE_KEYS,
}


def check_section(table: dict, section: str, source: str) -> None:
    """Check a workflow table against :data:`SCHEMA` (:func:`calib.config.check_table`)."""
    check_table(table, SCHEMA[section], section, source)


@dataclass(frozen=True)
class Workflow:
    """A loaded workflow file: every section typed and checked (:func:`load_workflow`).

    Parameters
    ----------
    name, description : str
    source : str
        The workflow file (named in errors).
    base_dir : str
        Its folder: relative paths start there.
    stages : tuple of calib.workflow.sections.Stage
    model : BemModelTable or FmuModelTable
        ``[model]`` (the native BEM's defaults when absent).
    calibration : calib.workflow.sections.CalibrationSection
        ``[calibration]``: the validated settings, ``force`` and ``strict_units``.
    executor : ExecutorSettings
        ``[executor]`` (serial when absent).
    fluid : calib.workflow.sections.Fluid
    rotor : dict, optional
        The ``[rotor]`` table (read by :func:`calib.rotor.sources.rotor_from_table`).
    grid : calib.workflow.sections.GridTable, optional
    measurements : calib.workflow.sections.MeasurementsTable, optional
        The measured data; else synthetic data of ``conditions``, ``truth`` and ``noise``.
    conditions, truth, noise : optional
        :class:`~calib.workflow.sections.Conditions`, :class:`~calib.workflow.sections.Truth`,
        :class:`~calib.workflow.sections.Noise`.
    diagnosis : tuple, optional
        ``(DiagnosisSettings, channels or None)`` of ``[diagnosis]`` (:func:`calib.diagnosis.in_workflow.diagnosis_settings`).
    validation : calib.workflow.validation.ValidationSettings, optional
    """

    name: str
    source: str
    base_dir: str
    stages: tuple
    model: BemModelTable | FmuModelTable
    calibration: CalibrationSection
    executor: ExecutorSettings
    fluid: Fluid = Fluid()
    description: str = ""
    rotor: dict | None = None
    grid: GridTable | None = None
    measurements: MeasurementsTable | None = None
    conditions: Conditions | None = None
    truth: Truth | None = None
    noise: Noise | None = None
    diagnosis: tuple | None = None
    validation: ValidationSettings | None = None

    @property
    def is_fmu(self) -> bool:
        """Whether the model is an FMU (``[model] kind = "fmu"``)."""
        return isinstance(self.model, FmuModelTable)

    def with_noise(self, noise: str) -> "Workflow":
        """The workflow with ``noise`` in place of ``[calibration] noise`` (``calib run --noise``)."""
        return dataclasses.replace(self, calibration=self.calibration.with_noise(noise, self.source))


def load_workflow(path: str | Path) -> Workflow:
    """Read and validate a workflow TOML file.

    Returns
    -------
    Workflow
        Typed and frozen; every rule on its values has run.

    Raises
    ------
    InputError
        Syntax errors (with line and column), unknown keys, wrong types, values a rule refuses, missing keys;
        naming the file and the key path.
    """
    path = Path(path)
    data = read_toml(path, "workflow file", finite=True)  # no workflow setting is NaN or inf
    return workflow_from_table(data, str(path), path.parent)


def workflow_from_table(data: dict, source: str, base_dir, *, measured_elsewhere: bool = False) -> Workflow:
    """The :class:`Workflow` of a workflow's tables (as read from ``source``).

    Parameters
    ----------
    data : dict
        The top-level table.
    source : str
        The file the tables came from (named in errors).
    base_dir : str or Path
        Where relative paths start.
    measured_elsewhere : bool
        The measurements come from elsewhere (``calib diagnose --data``): no ``[measurements]`` or
        synthetic tables are asked for.

    Raises
    ------
    InputError
        As :func:`load_workflow`.
    """
    src = source
    check_section(data, "", src)
    sections = {
        "model": model_table(data.get("model"), src),
        "calibration": CalibrationSection.from_table(data.get("calibration"), src),
        "executor": ExecutorSettings.from_table(data.get("executor"), src),
        "fluid": Fluid.from_table(data.get("fluid"), src),
        **{key: cls.from_table(data[key], src) for key, cls in (
            ("grid", GridTable), ("conditions", Conditions), ("measurements", MeasurementsTable), ("truth", Truth),
            ("noise", Noise)) if key in data}}
    stages = stages_from_list(data["stages"], src)
    if not measured_elsewhere:
        _check_data_source(data, src)
    for section, why in tables_required(data).items():
        if section not in data:
            raise InputError(f"missing required key '{section}' ({why})", src, field=section)
    if "diagnosis" in data:
        if isinstance(sections["model"], FmuModelTable):
            raise InputError("a workflow's [diagnosis] runs on the native BEM only; remove [diagnosis], use "
                             "[model] kind = \"bem\", or diagnose the FMU with calib diagnose --config (its "
                             "[model] kind = \"fmu\")", src, field="diagnosis")
        if "measurements" not in data:
            raise InputError("[diagnosis] needs measured data ([measurements] file = ...)", src, field="diagnosis")
        dset, channels = diagnosis_settings(data["diagnosis"], src)
        sections["diagnosis"] = (dset, None if channels is None else tuple(channels))
    if "validation" in data:
        sections["validation"] = ValidationSettings.from_table(data["validation"], src)
    return Workflow(name=data["name"], source=src, base_dir=str(base_dir), stages=stages,
                    description=data.get("description", ""), rotor=data.get("rotor"), **sections)


def _check_data_source(data: dict, src: str) -> None:
    """Either ``[measurements]`` or all of the synthetic tables, not both."""
    has_file = "measurements" in data
    has_synth = "truth" in data or "noise" in data or "conditions" in data
    if has_file == has_synth:
        raise InputError("give either [measurements] file = ... or synthetic data ([conditions], [truth], "
                         "[noise]), not both or neither", src, field="measurements")
    if has_synth:
        for section in ("conditions", "truth", "noise"):
            if section not in data:
                raise InputError(f"synthetic measurements need a [{section}] table", src, field=section)


def tables_required(data: dict) -> dict[str, str]:
    """The tables a workflow needs beyond the schema's, by model kind: {table: why}.

    The native BEM needs ``[rotor]`` and ``[grid]``. An FMU given as a file needs neither: its
    parameters, channels and any correction nodes come from its mapping file. A bundled FMU
    variant is built from ``[rotor]`` and ``[grid]``; synthetic measurements come from the
    native BEM of ``[rotor]``.
    """
    model = data.get("model") if isinstance(data.get("model"), dict) else {}
    if model.get("kind", "bem") != "fmu":
        return {"rotor": "the native BEM's rotor", "grid": "the native BEM's correction grid"}
    need = {}
    if "variant" in model:
        need = {"rotor": "a bundled FMU variant is built for the workflow's rotor",
                "grid": "a bundled FMU variant is built with the workflow's correction grid"}
    if "measurements" not in data:
        need.setdefault("rotor", "synthetic measurements come from the native BEM of [rotor]")
    return need
