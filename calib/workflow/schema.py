"""The workflow file: its schema (one table per section, checked by :mod:`calib.config`) and loading it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.calibration.calibrator import CalibrationSettings
from calib.config import AUTO_OR_NUM, NUM, check_table, schema_of
from calib.errors import InputError
from calib.models.from_config import BEM_KEYS
from calib.tomlfile import read_toml

#: [model] keys of the native BEM (:data:`calib.models.from_config.BEM_KEYS`).
MODEL_KEYS = BEM_KEYS
#: [calibration] keys: every CalibrationSettings field (same name, same default), plus ``force`` and
#: ``strict_units``.
CALIBRATION_KEYS = {**schema_of(CalibrationSettings, exclude=("verbose",),
                                   overrides={"sigma_bar": AUTO_OR_NUM, "sigma": dict, "relative_sigma": dict,
                                              "prior_std": dict, "cd_min": NUM, "max_retained": int,
                                              "band_eta": list}),
                    "force": (bool, False), "strict_units": (bool, False)}

# schema: section -> key -> (accepted types, required)
SCHEMA = {
    "": {"name": (str, True), "description": (str, False), "rotor": (dict, False), "model": (dict, False),
         "fluid": (dict, False), "grid": (dict, False), "conditions": (dict, False), "measurements": (dict, False),
         "truth": (dict, False), "noise": (dict, False), "calibration": (dict, False),
         "executor": (dict, False), "diagnosis": (dict, False), "validation": (dict, False),
         "stages": (list, True)},
    "rotor": None,  # validated by calib.rotor.sources.rotor_from_table (name | openfast | aerodyn | ... )
    "model": MODEL_KEYS,
    "fluid": {"density": (NUM, False), "kinematic_viscosity": (NUM, False)},
    "grid": {"alpha_nodes_deg": ((list, str), True), "eta_nodes": (list, True), "cl_scale": (NUM, False),
             "cd_scale": (NUM, False), "cl_bound": (NUM, False), "cd_bound": (NUM, False),
             "cd_floor": (NUM, False), "n_alpha_nodes": (int, False), "alpha_percentiles": (list, False)},
    "conditions": {"tsr": (list, True), "pitch": (list, True), "rotor_speed": (NUM, True),
                   "air_density": (NUM, False), "yaw": (NUM, False)},
    "measurements": {"file": (str, True), "drop_incomplete_rows": (bool, False), "time_series": (str, False),
                     "average_from": (NUM, False)},
    "truth": {"pitch_offset": (NUM, False), "wind_scale": (NUM, False), "alpha_step_deg": (NUM, False),
              "eta_step": (NUM, False), "bumps": (list, True)},
    "truth.bumps": {"block": (str, True), "amplitude": (NUM, True), "alpha_deg": (NUM, True),
                    "alpha_width": (NUM, True), "eta": (NUM, False), "eta_width": (NUM, False),
                    "eta_range": (list, False), "edge_width": (NUM, False)},
    "noise": {"relative": (dict, True), "seed": (int, False)},
    "calibration": CALIBRATION_KEYS,
    "stages": {"name": (str, True), "channels": (list, True), "retain": (str, False)},
}
def check_section(table: dict, section: str, source: str) -> None:
    """Check a workflow table against :data:`SCHEMA` (:func:`calib.config.check_table`)."""
    check_table(table, SCHEMA[section], section, source)


def number_array(value, key: str, source: str) -> np.ndarray:
    """An array of numbers, or ``{start, stop, num}`` written as [start, stop, "num"]-free lists only."""
    if (not isinstance(value, (list, tuple)) or not value
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise InputError(f"'{key}' must be a non-empty array of numbers, got {value!r}", source, field=key)
    out = np.asarray(value, float)
    if not np.all(np.isfinite(out)):
        raise InputError(f"'{key}' must be finite numbers, got {value!r}", source, field=key)
    return out


def load_workflow(path: str | Path) -> dict:
    """Read and validate a workflow TOML file.

    Raises
    ------
    InputError
        Syntax errors (with line and column), unknown keys, wrong types, missing keys.
    """
    path = Path(path)
    src = str(path)
    data = read_toml(path, "workflow file", finite=True)  # no workflow setting is NaN or inf
    check_section(data, "", src)
    for section in ("model", "grid", "conditions", "measurements", "truth", "noise", "calibration"):
        if section == "model" and data.get("model", {}).get("kind") == "fmu":
            continue  # an FMU's [model] table is validated by calib.models.from_config.model_from_workflow
        if section in data:
            check_section(data[section], section, src)
    for k, bump in enumerate(data.get("truth", {}).get("bumps", [])):
        if not isinstance(bump, dict):
            raise InputError("each truth.bumps entry must be a table", src, field=f"truth.bumps[{k}]")
        check_section(bump, "truth.bumps", src)
        if bump["block"] not in ("lift", "drag"):
            raise InputError(f"block must be 'lift' or 'drag', got {bump['block']!r}", src,
                             field=f"truth.bumps[{k}].block")
        for key in ("alpha_width", "eta_width", "edge_width"):
            if key in bump and not bump[key] > 0:
                raise InputError(f"must be > 0, got {bump[key]!r}", src, field=f"truth.bumps[{k}].{key}")
        if "eta_range" in bump:
            lo_hi = number_array(bump["eta_range"], f"truth.bumps[{k}].eta_range", src)
            if lo_hi.size != 2 or not lo_hi[0] < lo_hi[1]:
                raise InputError(f"must be [lo, hi] with lo < hi (r/R), got {bump['eta_range']!r}", src,
                                 field=f"truth.bumps[{k}].eta_range")
    if "conditions" in data:  # the synthetic operating points: checked here, before any set-up
        for key in ("tsr", "pitch"):
            number_array(data["conditions"][key], f"conditions.{key}", src)
    for channel, fraction in data.get("noise", {}).get("relative", {}).items():
        if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not fraction >= 0:
            raise InputError(f"must be a noise fraction >= 0 of the channel's RMS, got {fraction!r}", src,
                             field=f"noise.relative.{channel}")
    if not data["stages"]:
        raise InputError("at least one stage is needed", src, field="stages")
    for k, stage in enumerate(data["stages"]):
        if not isinstance(stage, dict):
            raise InputError("each stages entry must be a table", src, field=f"stages[{k}]")
        check_section(stage, "stages", src)
    has_file = "measurements" in data
    has_synth = "truth" in data or "noise" in data or "conditions" in data
    if has_file == has_synth:
        raise InputError("give either [measurements] file = ... or synthetic data ([conditions], [truth], "
                         "[noise]), not both or neither", src, field="measurements")
    if has_synth:
        for section in ("conditions", "truth", "noise"):
            if section not in data:
                raise InputError(f"synthetic measurements need a [{section}] table", src, field=section)
    for section in tables_required(data):
        if section not in data:
            raise InputError(f"missing required key '{section}' ({tables_required(data)[section]})", src,
                             field=section)
    data["_source"] = src
    data["_dir"] = str(path.parent)
    return data


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


