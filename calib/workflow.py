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
import sys
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.errors import CalibError, InputError
from calib.measurements import Measurements, read_measurements, sha256_of, synthesize
from calib.models.base import FieldModel
from calib.types import OperatingConditions, nominal_vector
from calib.models.bem_model import BemModel
from calib.rotor.sources import rotor_from_table
from calib.unit_check import check_units

NUM = (int, float)
# schema: section -> key -> (accepted types, required)
SCHEMA = {
    "": {"name": (str, True), "description": (str, False), "rotor": (dict, True), "model": (dict, False),
         "grid": (dict, True), "conditions": (dict, False), "measurements": (dict, False),
         "truth": (dict, False), "noise": (dict, False), "calibration": (dict, False),
         "stages": (list, True)},
    "rotor": None,  # validated by calib.rotor.sources.rotor_from_table (name | openfast | aerodyn | ... )
    "model": {"nuisance": (list, False), "use_tilt": (bool, False), "n_sectors": (int, False),
              "shear_exponent": (NUM, False), "tip_loss": (bool, False), "hub_loss": (bool, False)},
    "grid": {"alpha_nodes_deg": (list, True), "eta_nodes": (list, True), "cl_scale": (NUM, False),
             "cd_scale": (NUM, False), "cl_bound": (NUM, False), "cd_bound": (NUM, False)},
    "conditions": {"tsr": (list, True), "pitch": (list, True), "rotor_speed": (NUM, True),
                   "air_density": (NUM, False), "yaw": (NUM, False)},
    "measurements": {"file": (str, True), "drop_incomplete_rows": (bool, False)},
    "truth": {"pitch_offset": (NUM, False), "wind_scale": (NUM, False), "alpha_step_deg": (NUM, False),
              "eta_step": (NUM, False), "bumps": (list, True)},
    "truth.bumps": {"block": (str, True), "amplitude": (NUM, True), "alpha_deg": (NUM, True),
                    "alpha_width": (NUM, True), "eta": (NUM, False), "eta_width": (NUM, False),
                    "eta_range": (list, False), "edge_width": (NUM, False)},
    "noise": {"relative": (dict, True), "seed": (int, False)},
    "calibration": {"sigma_bar": ((int, float, str), False), "prior_sigma": (NUM, False), "optimizer": (str, False),
                    "noise": (str, False),
                    "cd_min": (NUM, False), "max_relinearizations": (int, False),
                    "max_iterations": (int, False), "max_retained": (int, False), "force": (bool, False),
                    "sigma": (dict, False)},
    "stages": {"name": (str, True), "channels": (list, True), "retain": (str, False)},
}
TYPE_NAMES = {str: "a string", dict: "a table", list: "an array", bool: "true/false", int: "an integer",
              NUM: "a number", (int, float, str): "\"auto\" or a number"}


def _check_table(table: dict, section: str, source: str) -> None:
    spec = SCHEMA[section]
    where = (section + ".") if section else ""
    for key, value in table.items():
        if key not in spec:
            raise InputError(f"unknown key '{where}{key}'; valid keys here: {', '.join(sorted(spec))}",
                             source, field=f"{where}{key}")
        types, _ = spec[key]
        ok = isinstance(value, types) and not (types in (int, NUM) and isinstance(value, bool))
        if types is NUM and isinstance(value, bool):
            ok = False
        if not ok:
            raise InputError(f"'{where}{key}' must be {TYPE_NAMES.get(types, types)}, got {value!r}",
                             source, field=f"{where}{key}")
    for key, (_, required) in spec.items():
        if required and key not in table:
            raise InputError(f"missing required key '{where}{key}'", source, field=f"{where}{key}")


def _numbers(value, key: str, source: str) -> np.ndarray:
    """An array of numbers, or ``{start, stop, num}`` written as [start, stop, "num"]-free lists only."""
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value) or not value:
        raise InputError(f"'{key}' must be a non-empty array of numbers, got {value!r}", source, field=key)
    return np.asarray(value, float)


def load_workflow(path: str | Path) -> dict:
    """Read and validate a workflow TOML file.

    Raises
    ------
    InputError
        Syntax errors (with line and column), unknown keys, wrong types, missing keys.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise InputError("workflow file not found", src)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", src) from None
    _check_table(data, "", src)
    for section in ("model", "grid", "conditions", "measurements", "truth", "noise", "calibration"):
        if section in data:
            _check_table(data[section], section, src)
    for k, bump in enumerate(data.get("truth", {}).get("bumps", [])):
        if not isinstance(bump, dict):
            raise InputError("each truth.bumps entry must be a table", src, field=f"truth.bumps[{k}]")
        _check_table(bump, "truth.bumps", src)
        if bump["block"] not in ("lift", "drag"):
            raise InputError(f"block must be 'lift' or 'drag', got {bump['block']!r}", src,
                             field=f"truth.bumps[{k}].block")
    if not data["stages"]:
        raise InputError("at least one stage is needed", src, field="stages")
    for k, stage in enumerate(data["stages"]):
        if not isinstance(stage, dict):
            raise InputError("each stages entry must be a table", src, field=f"stages[{k}]")
        _check_table(stage, "stages", src)
    has_file = "measurements" in data
    has_synth = "truth" in data or "noise" in data or "conditions" in data
    if has_file == has_synth:
        raise InputError("give either [measurements] file = ... or synthetic data ([conditions], [truth], "
                         "[noise]), not both or neither", src, field="measurements")
    if has_synth:
        for section in ("conditions", "truth", "noise"):
            if section not in data:
                raise InputError(f"synthetic measurements need a [{section}] table", src, field=section)
    data["_source"] = src
    data["_dir"] = str(path.parent)
    return data


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
    if isinstance(model, FieldModel) and result.alpha_seen.size:
        field = model.correction_field()
        a, e = result.alpha_seen, result.eta_seen
        tl, td = smooth_field(truth["bumps"], a, e)
        prior = result.prior_std if result.settings.get("representation_error", True) else None
        cov = field.coverage(result.p_hat, result.cov_p, a, e, tl, td, result.settings.get("band_confidence", 0.95),
                             prior)
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


def _conditions(cfg: dict, rotor, src: str) -> OperatingConditions:
    tsr = _numbers(cfg["tsr"], "conditions.tsr", src)
    pitch = _numbers(cfg["pitch"], "conditions.pitch", src)
    if np.any(tsr <= 0):
        raise InputError("tip-speed ratios must be > 0", src, field="conditions.tsr")
    T, P = np.meshgrid(tsr, pitch, indexing="ij")
    rpm = float(cfg["rotor_speed"])
    if rpm <= 0:
        raise InputError("rotor_speed must be > 0 rpm", src, field="conditions.rotor_speed")
    v = rpm * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, rpm), P.ravel(), float(cfg.get("air_density", 1.225)),
                               float(cfg.get("yaw", 0.0)))


def _absolute_rotor_table(table: dict, base_dir) -> dict:
    """The ``[rotor]`` table with file paths made absolute (results rebuild the rotor from it)."""
    out = dict(table)
    for key in ("openfast", "aerodyn", "aerodyn_blade", "windio"):
        if isinstance(out.get(key), str):
            out[key] = str((Path(base_dir) / out[key]).resolve())
    if isinstance(out.get("airfoils"), list):
        out["airfoils"] = [str((Path(base_dir) / a).resolve()) if isinstance(a, str) else a for a in out["airfoils"]]
    return out


def run_workflow(path: str | Path, out_dir: str | Path, progress: bool = True,
                 force: bool = False) -> list[StageOutcome]:
    """Run a workflow file; writes results, figures and ``report.html`` into ``out_dir``.

    ``force`` (or ``[calibration] force = true``) calibrates even when the unit check
    (:func:`calib.unit_check.check_units`) suspects a unit mistake; the report says so.
    """
    from calib.report.figures import plot_spectra, save_figure, write_figures
    from calib.report.html import write_report

    cfg = load_workflow(path)
    src = cfg["_source"]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rsrc = rotor_from_table(cfg["rotor"], src, cfg["_dir"])
    rotor = rsrc.rotor
    rotor_spec = _absolute_rotor_table(cfg["rotor"], cfg["_dir"])
    mcfg = cfg.get("model", {})
    settings = BemSettings(use_tilt=mcfg.get("use_tilt", False), n_sectors=mcfg.get("n_sectors"),
                           shear_exponent=float(mcfg.get("shear_exponent", 0.0)),
                           tip_loss=mcfg.get("tip_loss", True), hub_loss=mcfg.get("hub_loss", True))
    nuisance = tuple(mcfg.get("nuisance", ["pitch_offset"]))
    g = cfg["grid"]
    grid = CorrectionGrid(_numbers(g["alpha_nodes_deg"], "grid.alpha_nodes_deg", src),
                          _numbers(g["eta_nodes"], "grid.eta_nodes", src),
                          **{k: float(g[k]) for k in ("cl_scale", "cd_scale", "cl_bound", "cd_bound") if k in g})
    all_channels = list(dict.fromkeys(c for s in cfg["stages"] for c in s["channels"]))
    for k, s in enumerate(cfg["stages"]):
        if not all(isinstance(c, str) for c in s["channels"]) or not s["channels"]:
            raise InputError("channels must be a non-empty array of names", src, field=f"stages[{k}].channels")
    calib_cfg = dict(cfg.get("calibration", {}))
    force = bool(calib_cfg.pop("force", False)) or force

    t0 = time.perf_counter()
    unit_notes = {}
    if "measurements" in cfg:
        file = Path(cfg["_dir"]) / cfg["measurements"]["file"]
        meas = read_measurements(file, all_channels,
                                 drop_incomplete_rows=cfg["measurements"].get("drop_incomplete_rows", False))
        truth_p = None
        if progress:
            for note in meas.notes:
                print(f"[calib run] {file.name}: {note}", flush=True)
        check_model = BemModel(rotor, grid, all_channels, settings, nuisance, rotor_source=rotor_spec)
        unit_report = check_units(check_model, nominal_vector(check_model.parameters), meas,
                                  sigma=calib_cfg.get("sigma"))
        if progress:
            print("[calib run] " + unit_report.summary().replace("\n", "\n[calib run] "), flush=True)
        if not force:
            unit_report.raise_if_failed(str(file))
        elif not unit_report.ok:
            unit_notes = {"unit check (overridden by force)": "; ".join(f.message for f in unit_report.findings)}
    else:
        cond = _conditions(cfg["conditions"], rotor, src)
        noise = cfg["noise"]
        rel = noise["relative"]
        missing = [c for c in all_channels if c not in rel]
        if missing:
            raise InputError(f"no noise level for channel(s) {', '.join(missing)}", src,
                             field=f"noise.relative.{missing[0]}")
        tmodel, truth_p = truth_model(rotor, all_channels, settings, cfg["truth"], nuisance)
        meas = synthesize(tmodel, truth_p, cond, relative_sigma={c: float(rel[c]) for c in all_channels},
                          channels=all_channels, seed=int(noise.get("seed", 0)), source=f"synthetic ({src})")
        meas.write_csv(out / "measurements.csv")
    if progress:
        print(f"[calib run] {cfg['name']}: rotor {rotor.name}, {meas.n_points} operating points, "
              f"channels {', '.join(meas.channels)} ({time.perf_counter() - t0:.1f} s)", flush=True)

    outcomes = []
    for k, stage in enumerate(cfg["stages"]):
        name = stage["name"]
        model = BemModel(rotor, grid, stage["channels"], settings, nuisance, rotor_source=rotor_spec)
        st = CalibrationSettings(retain=stage.get("retain", "threshold"), verbose=False, **calib_cfg)
        st.validate(src)
        callback = None
        if progress:
            def callback(rec, _name=name):
                if rec.get("stage") == "relinearize":
                    print(f"[calib run] {_name}: re-linearization {rec.get('iteration')}: "
                          f"{rec.get('n_retained')} retained, cost {rec.get('cost', float('nan')):.4g}", flush=True)
        cal = Calibrator(model, meas.select_channels(stage["channels"]), st, callback, name=name)
        t_cal = time.perf_counter()
        res = cal.run()
        t_cal = time.perf_counter() - t_cal
        res.inputs[src] = sha256_of(src)
        res.inputs["workflow"] = cfg["name"]
        res.checks.update(unit_notes)
        if truth_p is not None:
            res.checks.update(truth_checks(model, res, cfg["truth"]))
        stage_dir = out / f"stage{k + 1}_{''.join(ch if ch.isalnum() else '_' for ch in name)}"
        stage_dir.mkdir(exist_ok=True)
        t_rep = time.perf_counter()
        res.save(stage_dir)
        figs = write_figures(res, stage_dir)
        t_rep = time.perf_counter() - t_rep
        outcomes.append(StageOutcome(name, res, figs, stage_dir))
        if progress:
            print(f"[calib run] {name}: {res.summary().splitlines()[0].split(': ', 1)[-1]}; {res.n_retained} of "
                  f"{res.n_params} retained; chi2/dof {res.chi2_per_dof_before:.3g} -> {res.chi2_per_dof_after:.3g}; "
                  f"calibration {t_cal:.1f} s, figures {t_rep:.1f} s; results in {stage_dir}", flush=True)
            for label, text in res.checks.items():
                print(f"[calib run] {name}: {label}: {text}", flush=True)
    extra = {}
    if len(outcomes) > 1:
        fig = plot_spectra({o.name: o.result for o in outcomes})
        extra["singular_value_spectra"] = save_figure(fig, out, "singular_value_spectra")
    intro = cfg.get("description", "")
    if truth_p is not None:
        intro += " Measurements are synthetic: a truth model with a smooth correction field sampled on a fine " \
                 "grid (not in the span of the calibration's shape functions) plus seeded Gaussian noise."
    report = write_report(out / "report.html", title=f"calib: {cfg['name']}",
                          results={o.name: o.result for o in outcomes},
                          figures={o.name: o.figures for o in outcomes}, intro=intro, extra_figures=extra,
                          checks={o.name: o.result.checks for o in outcomes})
    if progress:
        print(f"[calib run] report: {report}", flush=True)
    return outcomes


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="calib run", description="run a workflow TOML file")
    parser.add_argument("file")
    parser.add_argument("--out", required=True)
    parser.add_argument("--force", action="store_true")
    args = parser.parse_args(argv)
    try:
        run_workflow(args.file, args.out, force=args.force)
    except CalibError as exc:
        print(f"calib: error: {exc}", file=sys.stderr)
        return 2
    return 0


__all__ = ["Measurements", "SCHEMA", "load_workflow", "main", "run_workflow", "smooth_field", "truth_model"]
