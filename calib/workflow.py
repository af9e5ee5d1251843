"""TOML workflows: ``calib run FILE --out DIR``.

A workflow names a rotor and a correction grid, gets measurements (a CSV file, or
synthetic ones from a *truth* model with seeded noise), and runs one or more
calibration *stages* (e.g. hub loads only, then hub plus blade loads). It writes, per
stage, the result (``result.json`` + ``result.npz``) and the figures, and one
self-contained ``report.html`` that collects them. The schema is documented in
``workflows/README.md``; unknown keys and wrong types are rejected with the file and the
key in the message.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.config import AUTO_OR_NUM, NUM, check_table, schema_of
from calib.corrections import CorrectionGrid
from calib.errors import CalibError, InputError
from calib.measurements import Measurements, read_measurements, sha256_of, synthesize
from calib.bem.polar_grid import AIR_KINEMATIC_VISCOSITY
from calib.types import STANDARD_AIR_DENSITY, OperatingConditions, nominal_vector
from calib.models.bem_model import BemModel
from calib.models.registry import MODEL_KINDS
from calib.rotor.sources import absolute_table, file_provenance, rotor_from_table
from calib.tomlfile import read_toml
from calib.setup_statement import statement, statement_html, statement_lines
from calib.unit_check import apply_unit_check
from calib.logs import add_output_arguments, say

log = logging.getLogger("calib.workflow")


#: [model] keys of the native BEM: every BemSettings field (same name, same default) except the fluid's
#: viscosity (in [fluid]), plus rotor overrides and the nuisance list.
MODEL_KEYS = {**schema_of(BemSettings, exclude=("kinematic_viscosity",),
                             overrides={"n_sectors": int, "polar_smoothing": list}),
              "kind": (str, False), "tilt": (NUM, False), "precone": (NUM, False), "yaw": (NUM, False),
              "nuisance": (list, False)}
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


def _numbers(value, key: str, source: str) -> np.ndarray:
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
            lo_hi = _numbers(bump["eta_range"], f"truth.bumps[{k}].eta_range", src)
            if lo_hi.size != 2 or not lo_hi[0] < lo_hi[1]:
                raise InputError(f"must be [lo, hi] with lo < hi (r/R), got {bump['eta_range']!r}", src,
                                 field=f"truth.bumps[{k}].eta_range")
    if "conditions" in data:  # the synthetic operating points: checked here, before any set-up
        for key in ("tsr", "pitch"):
            _numbers(data["conditions"][key], f"conditions.{key}", src)
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


# ----------------------------------------------------------------------------- truth fields
def smooth_field(bumps: list[dict], alpha_deg, eta):
    """ΔC_L, ΔC_D of a sum of smooth bumps (Gaussian in α; Gaussian or smooth box in η).

    A bump with ``eta_range = [a, b]`` is a box in η with tanh edges of width ``edge_width``
    [-] (default 0.03), to localize a correction on one airfoil's span range.
    """
    alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
    out = {"lift": np.zeros(alpha_deg.shape), "drag": np.zeros(alpha_deg.shape)}
    for b in bumps:
        fa = np.exp(-0.5 * ((alpha_deg - b["alpha_deg"]) / b["alpha_width"]) ** 2)
        if "eta_range" in b:
            lo, hi = b["eta_range"]
            w = b.get("edge_width", 0.03)
            fe = 0.25 * (1 + np.tanh((eta - lo) / w)) * (1 - np.tanh((eta - hi) / w))
        else:
            fe = np.exp(-0.5 * ((eta - b.get("eta", 0.5)) / b.get("eta_width", 0.2)) ** 2)
        out[b["block"]] += b["amplitude"] * fa * fe
    return out["lift"], out["drag"]


def truth_model(rotor, channels, settings, truth: dict, nuisance):
    """A BemModel whose fine correction grid samples the smooth truth field, and its p."""
    da = float(truth.get("alpha_step_deg", 1.0))
    de = float(truth.get("eta_step", 0.025))
    grid = CorrectionGrid(np.arange(-30.0, 60.0 + da / 2, da), np.arange(0.0, 1.0 + de / 2, de),
                          cl_bound=10.0, cd_bound=10.0)
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    dcl, dcd = smooth_field(truth["bumps"], A, E)
    model = BemModel(rotor, grid, channels, settings, nuisance)
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = dcl.reshape(-1)
    p[grid.n_lift:grid.n_params] = dcd.reshape(-1)
    for j, name in enumerate(nuisance):
        if name in truth:
            p[grid.n_params + j] = float(truth[name])
    return model, p


def truth_checks(model, result, truth: dict) -> dict[str, str]:
    """Statements about a synthetic run against its known truth: band coverage, nuisance errors.

    Coverage is counted at the (α, η) points the operating points reach, with the same bands
    the report draws (frozen-direction prior and representation variance included).
    """
    out = {}
    if model.capabilities.correction_field and result.alpha_seen.size:
        field = model.correction_field()
        a, e = result.alpha_seen, result.eta_seen
        tl, td = smooth_field(truth["bumps"], a, e)
        prior = result.prior_std if result.settings.get("representation_error", True) else None
        # a result saved before the smooth-field prior had independent nodes (correlation length 0)
        cov = field.coverage(result.p_hat, result.cov_p, a, e, tl, td, result.settings.get("band_confidence", 0.95),
                             prior, correlation_length=float(result.settings.get("prior_correlation", 0.0)),
                             cd_min=result.settings.get("cd_min"))
        out["coverage of the known truth"] = (
            f"the {100 * cov['confidence']:.0f} % bands contain the true ΔC_L at {100 * cov['lift']:.1f} % and the "
            f"true ΔC_D at {100 * cov['drag']:.1f} % of the {cov['n_points']} (α, η) points the operating points reach")
    for v in result.verdicts:
        if v["name"] in truth and v["std"] > 0:
            z = (v["value"] - float(truth[v["name"]])) / v["std"]
            out[f"{v['name']} against its truth"] = (f"estimate {v['value']:.4g} ± {v['std']:.2g} {v['unit']}, truth "
                                                     f"{float(truth[v['name']]):.4g}: {z:+.1f}σ")
    return out


# ----------------------------------------------------------------------------- running
@dataclass
class StageOutcome:
    name: str
    result: object
    figures: dict
    out_dir: Path


def _conditions(cfg: dict, rotor, src: str, density: float = STANDARD_AIR_DENSITY, yaw: float = 0.0) -> OperatingConditions:
    tsr = _numbers(cfg["tsr"], "conditions.tsr", src)
    pitch = _numbers(cfg["pitch"], "conditions.pitch", src)
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
    validation: object = None             # calib.validation.ValidationSettings of [validation]
    strict_units: bool = False            # [calibration] strict_units: a misfit no unit factor explains stops
    rotor_files: dict | None = None       # provenance of the rotor files read (calib.rotor.sources.file_provenance)
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
            eta_nodes = _numbers(g["eta_nodes"], "grid.eta_nodes", src)
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
            alpha = _numbers(alpha, "grid.alpha_nodes_deg", src)
        eta = _numbers(g["eta_nodes"], "grid.eta_nodes", src)
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
    mcfg = dict(cfg.get("model", {}))
    kind = mcfg.pop("kind", "bem")
    if kind not in MODEL_KINDS:
        raise InputError(f"unknown model kind {kind!r}; valid: {', '.join(MODEL_KINDS)}", src, field="model.kind")
    fmu_table = None
    if kind == "fmu":
        fmu_table, mcfg = {"kind": "fmu", **mcfg}, {}
        if "measurements" not in cfg:
            notes.append("synthetic measurements come from the native BEM; the FMU is calibrated to them")
    overrides = {}
    for key, attr in (("tilt", "tilt_deg"), ("precone", "precone_deg")):
        if key in mcfg:
            value = float(mcfg.pop(key))
            if not -30.0 <= value <= 30.0:
                raise InputError(f"must be an angle in degrees within ±30, got {value!r}", src, field=f"model.{key}")
            overrides[attr] = value
            notes.append(f"{key} {value:g} deg from [model] (rotor files: {getattr(rotor, attr):g} deg)")
    if overrides:
        rotor = dataclasses.replace(rotor, **overrides)
    nuisance = tuple(mcfg.pop("nuisance", ["pitch_offset"]))
    yaw = float(mcfg.pop("yaw", 0.0))
    if not -90.0 < yaw < 90.0:
        raise InputError(f"must be a yaw misalignment in degrees within ±90, got {yaw!r}", src, field="model.yaw")
    kwargs = {}
    for key, value in mcfg.items():
        kwargs[key] = tuple(value) if key == "polar_smoothing" else value
    origins = {}
    for key, attr in FILE_SETUP.items() if rsrc is not None else ():
        file_value = getattr(rsrc, attr, None)
        if key not in kwargs and file_value is not None:
            kwargs[key] = file_value
            origins[key] = "rotor files"
            notes.append(f"{key} = {file_value} from the rotor files")
    fluid_table = dict(cfg.get("fluid", {}))
    for key, attr in (("density", "air_density"), ("kinematic_viscosity", "kinematic_viscosity")):
        origins[key] = f"[fluid] {key}" if key in fluid_table else "rotor files" \
            if getattr(rsrc, attr, None) else "default (air at 15 °C)"
    fluid = dict(cfg.get("fluid", {}))
    density = float(fluid.get("density", getattr(rsrc, "air_density", None) or AIR["density"]))
    viscosity = float(fluid.get("kinematic_viscosity", getattr(rsrc, "kinematic_viscosity", None)
                                or AIR["kinematic_viscosity"]))
    for key, value in (("density", density), ("kinematic_viscosity", viscosity)):
        if not value > 0:
            raise InputError(f"must be > 0, got {value!r}", src, field=f"fluid.{key}")
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
    channels = []
    for k, s in enumerate(cfg["stages"]):
        if not s["channels"] or not all(isinstance(c, str) for c in s["channels"]):
            raise InputError("channels must be a non-empty array of names", src, field=f"stages[{k}].channels")
        channels += [c for c in s["channels"] if c not in channels]
    _check_channels(fmu_table, rotor, settings, channels, src, cfg["_dir"])
    calib_cfg = dict(cfg.get("calibration", {}))
    force = bool(calib_cfg.pop("force", False))
    strict_units = bool(calib_cfg.pop("strict_units", False))
    if "band_eta" in calib_cfg:
        calib_cfg["band_eta"] = tuple(calib_cfg["band_eta"])
    cal = CalibrationSettings(**calib_cfg).validate(src, "calibration.")
    g = cfg.get("grid")
    if g is not None and isinstance(g["alpha_nodes_deg"], str) and g["alpha_nodes_deg"] != "auto":
        raise InputError(f"must be an array of angles [deg] or \"auto\", got {g['alpha_nodes_deg']!r}", src,
                         field="grid.alpha_nodes_deg")
    rotor_spec = absolute_table(cfg["rotor"], cfg["_dir"]) if "rotor" in cfg else None
    setup = WorkflowSetup(rotor, rotor_spec, settings, nuisance, density,
                          channels, calib_cfg, cal, force, g, src, notes, fmu_table, cfg.get("executor"),
                          cfg["_dir"], yaw)
    if fmu_table is not None and not setup.uses_grid:
        if g is not None:
            notes.append("[grid] is not used: the FMU's correction nodes, if any, come from its mapping file")
        if rotor is not None and "measurements" in cfg:
            notes.append("[rotor] is not used by the FMU (it carries its own rotor); only stated")
    elif not isinstance(g["alpha_nodes_deg"], str):
        setup.grid(OperatingConditions([1.0], [1.0], [0.0]))  # validate the explicit grid now
    from calib.diagnosis.in_workflow import diagnosis_settings
    from calib.validation import ValidationSettings
    if "diagnosis" in cfg:
        if fmu_table is not None:
            raise InputError("a workflow's [diagnosis] runs on the native BEM only; remove [diagnosis], use "
                             "[model] kind = \"bem\", or diagnose the FMU with calib diagnose --config (its "
                             "[model] kind = \"fmu\")", src, field="diagnosis")
        if "measurements" not in cfg:
            raise InputError("[diagnosis] needs measured data ([measurements] file = ...)", src, field="diagnosis")
        setup.diagnosis = diagnosis_settings(cfg["diagnosis"], src)
    if "validation" in cfg:
        setup.validation = ValidationSettings.from_table(cfg["validation"], src)
    setup.strict_units = strict_units
    setup.origins = origins
    if rsrc is not None and rsrc.files:
        setup.rotor_files = file_provenance(rsrc.files, cfg["_dir"])
    return setup


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


def run_workflow(path: str | Path, out_dir: str | Path, progress: bool = True,
                 force: bool = False, resume: bool = False, history: bool = True,
                 strict_units: bool = False) -> list[StageOutcome]:
    """Run a workflow file; writes results, figures and ``report.html`` into ``out_dir``.

    Parameters
    ----------
    path : str or Path
        The workflow TOML file.
    out_dir : str or Path
        Output folder.
    progress : bool
        Print progress lines (logged under ``calib.workflow`` either way).
    force : bool
        Calibrate even when the unit check (:func:`calib.unit_check.apply_unit_check`) finds
        a unit factor that explains the data (also ``[calibration] force = true``); the report
        says so.
    strict_units : bool
        Also stop when the nominal model misses the data and no unit factor explains it (also
        ``[calibration] strict_units = true``); by default such a misfit is printed as a
        warning and calibrated.
    resume : bool
        Continue the killed run whose history is in ``out_dir`` (:mod:`calib.history`): every
        model call it completed is read back instead of computed; refused when the workflow,
        the measurement file or the rotor's geometry and polars changed since.
    history : bool
        Keep the history in ``out_dir/history`` (model calls and iterations as they happen).
    """
    cfg = load_workflow(path)
    src = cfg["_source"]
    # everything the settings can get wrong is found here, before any data is read
    setup = prepare(cfg)
    force = setup.force or force
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for note in setup.notes:
        say(log, f"[calib run] set-up: {note}", progress)
    hist = None
    if history or resume:
        from calib.history import open_history
        from calib.history import content_digest
        inputs = {**run_inputs(cfg), "rotor (geometry and polars)": content_digest(setup.rotor)
                  if setup.rotor is not None else None}
        hist = open_history(out, {"command": "run", "workflow": str(Path(src).resolve()), "inputs": inputs}, resume)
        hist.event("start", resumed=resume, records=hist.n_records)
        if resume:
            say(log, f"[calib run] resuming from {hist.folder}: {hist.n_records} model calls on record", progress)

    from calib.models.from_config import executor_from_table
    executor = executor_from_table(setup.executor_table, src)
    try:
        outcomes = _run(cfg, setup, out, executor, progress, force, hist, strict_units)
    finally:
        executor.close()
    if hist is not None:
        hist.event("finished", computed=hist.computed, replayed=hist.replayed)
        say(log, f"[calib run] model calls: {hist.computed} computed, {hist.replayed} read back from "
                 f"{hist.folder}", progress)
    return outcomes


def _run(cfg, setup, out, executor, progress, force, hist=None, strict=False):
    from calib.history import recorded
    from calib.logs import progress_line
    from calib.report.figures import plot_spectra, save_figure, write_figures
    from calib.report.html import write_report

    def echo(line):
        say(log, line, progress)

    # an FMU's calls are recorded in chunks of points (a kill loses at most one chunk of simulations)
    chunk = max(int(executor.workers if executor is not None else 1), 1) if setup.fmu_table is not None else None

    src = cfg["_source"]
    rotor, settings, nuisance = setup.rotor, setup.settings, setup.nuisance
    all_channels, calib_cfg = setup.channels, setup.calibration
    t0 = time.perf_counter()
    unit_notes = {}
    if "measurements" in cfg:
        file = Path(cfg["_dir"]) / cfg["measurements"]["file"]
        meas = measurements_of(cfg, all_channels)
        if "air_density" not in meas.metadata.get("units", {}):
            meas = dataclasses.replace(meas, conditions=dataclasses.replace(
                meas.conditions, air_density=np.full(meas.n_points, setup.density)))
        if "yaw" not in meas.metadata.get("units", {}) and setup.yaw != 0.0:
            meas = dataclasses.replace(meas, conditions=dataclasses.replace(
                meas.conditions, yaw=np.full(meas.n_points, setup.yaw)))
        truth_p = None
        for note in meas.notes:
            echo(f"[calib run] {file.name}: {note}")
        set_up = statement(setup, cfg, meas)
        for line in statement_lines(set_up):
            echo(f"[calib run] set-up in force: {line}")
        grid = setup.grid(meas.conditions, progress)
        check_model = recorded(setup.model(grid, all_channels, executor), hist, "unit check", chunk, progress_line)
        _, unit_notes = apply_unit_check(check_model, nominal_vector(check_model.parameters), meas,
                                         sigma=calib_cfg.get("sigma"), force=force,
                                         strict=strict or setup.strict_units, source=str(file),
                                         printer=echo, model_units=setup.model_units())
    else:
        cond = _conditions(cfg["conditions"], rotor, src, setup.density, setup.yaw)
        grid = setup.grid(cond, progress)
        noise = cfg["noise"]
        rel = noise["relative"]
        missing = [c for c in all_channels if c not in rel]
        if missing:
            raise InputError(f"no noise level for channel(s) {', '.join(missing)}", src,
                             field=f"noise.relative.{missing[0]}")
        set_up = statement(setup, cfg)
        for line in statement_lines(set_up):
            echo(f"[calib run] set-up in force: {line}")
        tmodel, truth_p = truth_model(rotor, all_channels, settings, cfg["truth"], nuisance)
        meas = synthesize(tmodel, truth_p, cond, relative_sigma={c: float(rel[c]) for c in all_channels},
                          channels=all_channels, seed=int(noise.get("seed", 0)), source=f"synthetic ({src})")
        meas.write_csv(out / "measurements.csv")
    echo(f"[calib run] {cfg['name']}: {setup.model_name()}, {meas.n_points} operating points, "
         f"channels {', '.join(meas.channels)} ({time.perf_counter() - t0:.1f} s)")

    from calib import validation
    from calib.diagnosis import in_workflow

    effects, diag, validations = [], None, {}
    if setup.diagnosis is not None:   # the discrepancy workflow first; its named effects join every stage
        effects, diag = in_workflow.run_diagnosis(setup, meas, grid, out, executor, echo, hist)
    outcomes = []
    for k, stage in enumerate(cfg["stages"]):
        name = stage["name"]
        raw_model = setup.model(grid, stage["channels"], executor, effects)
        model = recorded(raw_model, hist, f"stage {k + 1}: {name}", chunk, progress_line)
        st = dataclasses.replace(setup.calibration_settings, retain=stage.get("retain",
                                                                            setup.calibration_settings.retain))
        st.validate(src, f"stages[{k}].")
        def callback(rec, _name=name):
            if hist is not None:
                hist.event("iteration", run=_name, **rec)
            if rec.get("stage") == "relinearize":
                echo(f"[calib run] {_name}: re-linearization {rec.get('iteration')}: "
                     f"{rec.get('n_retained')} retained, cost {rec.get('cost', float('nan')):.4g}")
            elif rec.get("stage") == "map_done":
                echo(f"[calib run] {_name}: MAP estimate {rec['status']} after {rec['iterations']} iteration(s), "
                     f"cost {rec['cost']:.4g}; the data determine {rec['data_beat_prior']} direction(s) better "
                     "than the prior")
            elif rec.get("stage") == "second_start":
                echo(f"[calib run] {_name}: χ² {rec['chi2']:.4g} over {rec['dof']} rejects the stated noise "
                     f"(p = {rec['p_value']:.2g}): the automatic choice starts again from the prior limit's count")
            elif rec.get("stage") == "second_start_done":
                echo(f"[calib run] {_name}: {rec['first_retained']} θ from nominal ({rec['first_status']}), "
                     f"{rec['second_retained']} θ from the limit ({rec['second_status']}); kept the "
                     f"{'second' if rec['second_kept'] else 'first'}")
            else:
                log.debug("%s: %s", _name, ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                                                       for k, v in rec.items() if k != "qp"))
        cal = Calibrator(model, meas.select_channels(stage["channels"]), st, callback, name=name)
        t_cal = time.perf_counter()
        res = cal.run()
        t_cal = time.perf_counter() - t_cal
        res.inputs[src] = sha256_of(src)
        res.inputs["workflow"] = cfg["name"]
        res.checks.update(unit_notes)
        res.checks.update(_fault_checks(raw_model))
        if truth_p is not None:
            res.checks.update(truth_checks(model, res, cfg["truth"]))
        if diag is not None:
            res.checks["discrepancy workflow"] = in_workflow.diagnosis_sentence(diag)
        if setup.validation is not None:
            kind = "leave-one-out" if setup.validation.split == "one" else "band split"
            val = validation.leave_one_out(
                lambda _c=tuple(stage["channels"]): setup.model(grid, list(_c), executor, effects),
                meas.select_channels(stage["channels"]), st, setup.validation,
                progress=lambda line, _n=name, _k=kind: echo(f"[calib run] {_n}: {_k}: {line}"))
            validations[name] = val
            res.checks.update({f"{kind} ({c})": val.sentence(c) for c in val.channels()})
        stage_dir = out / f"stage{k + 1}_{''.join(ch if ch.isalnum() else '_' for ch in name)}"
        stage_dir.mkdir(exist_ok=True)
        t_rep = time.perf_counter()
        res.save(stage_dir)
        if name in validations:
            validation.write_validation(validations[name], stage_dir)
        truth = (lambda a, e, _b=cfg["truth"]["bumps"]: smooth_field(_b, a, e)) if truth_p is not None else None
        figs = write_figures(res, stage_dir, truth=truth, progress=lambda line: echo(f"[calib run] {line}"))
        t_rep = time.perf_counter() - t_rep
        outcomes.append(StageOutcome(name, res, figs, stage_dir))
        if hist is not None:
            hist.event("stage_done", run=name, folder=stage_dir.name, status=res.status,
                       model_evaluations=res.failures.get("model_evaluations"),
                       model_jacobians=res.failures.get("model_jacobians"))
        kept = (f"the data beat the prior in {res.n_retained} of {res.n_params} directions" if res.estimator == "map"
                else f"{res.n_retained} of {res.n_params} retained")
        echo(f"[calib run] {name}: {res.summary().splitlines()[0].split(': ', 1)[-1]}; {kept}; "
             f"chi2/dof {res.chi2_per_dof_before:.3g} -> {res.chi2_per_dof_after:.3g}; "
             f"calibration {t_cal:.1f} s, figures {t_rep:.1f} s; results in {stage_dir}")
        for label, text in res.checks.items():
            echo(f"[calib run] {name}: {label}: {text}")
    extra = {}
    if len(outcomes) > 1:
        fig = plot_spectra({o.name: o.result for o in outcomes})
        extra["singular_value_spectra"] = save_figure(fig, out, "singular_value_spectra")
    if "measurements" in cfg and (diag is not None or validations):
        rotor_ch = [c for c in all_channels if "@" not in c]
        span_ch = [c for c in all_channels if c.startswith("cn@")]
        for key, chans, what in (("loads_vs_wind_speed", rotor_ch, "rotor loads"),
                                 ("cn_vs_wind_speed", span_ch, "normal-force coefficient at the pressure taps")):
            if chans:
                fig = validation.campaign_figure(setup, meas, grid, outcomes, diag, validations, effects, chans,
                                               f"{cfg['name']}: {what}, measured and modelled", executor)
                extra[key] = save_figure(fig, out, key)
        for k, o in enumerate(outcomes):
            fig = validation.informed_eigenshapes(o.result)
            if fig is not None:
                extra[f"informed_eigenshapes_stage{k + 1}"] = save_figure(fig, out, f"informed_eigenshapes_stage{k + 1}")
    intro = cfg.get("description", "")
    if truth_p is not None:
        intro += " Measurements are synthetic: a truth model with a smooth correction field sampled on a fine " \
                 "grid (not in the span of the calibration's shape functions) plus seeded Gaussian noise."
    report = write_report(out / "report.html", title=f"calib: {cfg['name']}",
                          sections=[statement_html(set_up)] + ([validation.section_html(diag, validations)]
                                                               if (diag or validations) else []),
                          results={o.name: o.result for o in outcomes},
                          figures={o.name: o.figures for o in outcomes}, intro=intro, extra_figures=extra,
                          checks={o.name: o.result.checks for o in outcomes})
    echo(f"[calib run] report: {report}")
    return outcomes


def _fault_checks(model) -> dict[str, str]:
    """An FMU stage's report lines on its simulations' faults: the timeout in force, the points
    quarantined and those with an error status (:func:`calib.fmu.faults.fault_sentences`);
    nothing for the native BEM."""
    from calib.models.bem_model import BemModel

    if isinstance(model, BemModel):
        return {}
    from calib.fmu.faults import fault_sentences
    from calib.fmu.model import FmuModel

    return fault_sentences(model.fault_summary()) if isinstance(model, FmuModel) else {}


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``calib run`` (shared by ``python -m calib.workflow`` and the ``calib`` command)."""
    parser.add_argument("file", nargs="?", default=None, help="workflow TOML file (with --resume: optional, "
                        "default the one the run started with; if given, it must be unchanged)")
    parser.add_argument("--out", default=None, help="output folder (required unless --resume DIR)")
    parser.add_argument("--force", action="store_true", help="calibrate even when the unit check suspects a unit "
                        "mistake in the measurements (the report says so)")
    parser.add_argument("--strict-units", action="store_true", help="also stop when the nominal model misses the "
                        "data and no unit factor explains it (default: a loud warning, then calibrate)")
    parser.add_argument("--resume", metavar="DIR", default=None, help="continue the killed run whose output "
                        "folder is DIR: model calls on record in DIR/history are read back, not computed again; "
                        "refused if the workflow, the measurement file or the rotor's data changed")
    add_output_arguments(parser, "also print every optimizer iteration and model call (the log file "
                         "DIR/calib.log always has them)")


def run_from_args(args) -> int:
    """``calib run`` from parsed arguments (see :func:`add_run_arguments`); returns the exit code."""
    from calib.logs import command_logging

    out, file = args.out, args.file
    if args.resume is not None:
        if out is not None and Path(out).resolve() != Path(args.resume).resolve():
            raise InputError(f"--out {out} and --resume {args.resume} name different folders; give one", "calib run",
                             field="--out")
        out = args.resume
        if file is None:
            manifest = Path(out) / "history" / "manifest.json"
            if not manifest.is_file():
                raise InputError(f"nothing to resume: no history/manifest.json in {out}", str(out), field="--resume")
            import json
            file = json.loads(manifest.read_text()).get("workflow")
    if file is None or out is None:
        raise InputError("give a workflow file and --out DIR (or --resume DIR)", "calib run",
                         field="file" if file is None else "--out")
    with command_logging(out, args.verbose, args.quiet):
        try:
            run_workflow(file, out, force=args.force, resume=args.resume is not None, history=not args.no_history,
                         strict_units=getattr(args, "strict_units", False))
        except CalibError as exc:      # printed on stderr by the caller; the log file keeps it too
            log.debug(f"calib: error: {exc}", exc_info=True)
            raise
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="calib run", description="run a workflow TOML file")
    add_run_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return run_from_args(args)
    except CalibError as exc:
        print(f"calib: error: {exc}", file=sys.stderr)
        return 2


__all__ = ["Measurements", "SCHEMA", "load_workflow", "main", "run_workflow", "smooth_field", "truth_model"]
