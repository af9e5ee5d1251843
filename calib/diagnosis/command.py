"""``calib diagnose --rotor ROTOR --data FILE.csv --out DIR [--config FILE.toml]``.

Reads the rotor (an embedded name, or a rotor file: ``.fst`` OpenFAST deck, ``.yaml``
windIO, ``.dat`` AeroDyn15 main file), the measurement table and, optionally, the
``[rotor]``, ``[model]``, ``[fluid]``, ``[grid]``, ``[calibration]`` and ``[diagnosis]``
tables of a workflow-style TOML file; checks the measurements' units against the nominal
model as ``calib run`` does (:func:`calib.checks.unit_check.apply_unit_check`: a unit factor that
explains the data stops it unless ``--force``); runs :func:`calib.diagnosis.core.diagnose`;
writes ``DIR/diagnosis.json`` and ``DIR/report.html``. A naming round or the recalibration
that fails ends the diagnosis early: what the rounds before it found is still written, with
the failure stated, and the command exits 0.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from calib.diagnosis.core import diagnose
from calib.diagnosis.in_workflow import diagnosis_settings
from calib.errors import CalibError, InputError
from calib.logs import add_output_arguments, say
from calib.measurements import read_measurements
from calib.report.setup_statement import statement, statement_lines
from calib.tomlfile import read_toml

CONFIG_TABLES = ("rotor", "model", "fluid", "grid", "calibration", "diagnosis", "executor")
DEFAULT_GRID = {"alpha_nodes_deg": "auto", "eta_nodes": [0.25, 0.5, 0.75, 1.0]}

log = logging.getLogger("calib.diagnosis.command")


def _rotor_table(rotor: str) -> dict:
    suffix = Path(rotor).suffix.lower()
    if suffix == ".fst":
        return {"openfast": str(Path(rotor).resolve())}
    if suffix in (".yaml", ".yml"):
        return {"windio": str(Path(rotor).resolve())}
    if suffix == ".dat":
        return {"aerodyn": str(Path(rotor).resolve())}
    return {"name": rotor}


def diagnose_inputs(rotor: str | None, data: str, config: str | None) -> dict:
    """What a diagnosis depends on, for its history manifest: {label: SHA-256 or value}."""
    from calib.measurements import sha256_of

    inputs = {"data file": sha256_of(data) if Path(data).is_file() else None,
              "config file": sha256_of(config) if config and Path(config).is_file() else None,
              "rotor": rotor}
    if rotor is not None and Path(rotor).is_file():
        inputs["rotor file"] = sha256_of(rotor)
    return inputs


def run_diagnose(rotor: str | None, data: str, out: str, config: str | None = None, printer=None,
                 resume: bool = False, history: bool = True, force: bool = False, strict_units: bool = False,
                 noise: str | None = None, prefix: str = "[calib diagnose]", facility: str | None = None):
    """Run the diagnosis from the command line's arguments; returns the Diagnosis.

    Parameters
    ----------
    rotor, data, out, config : str
        As ``calib diagnose --rotor --data --out --config``.
    force : bool
        Diagnose even when the unit check finds a unit factor that explains the data
        (``--force``, or ``[calibration] force = true``); the report says what was overridden.
    strict_units : bool
        Also stop when the nominal model misses the data and no unit factor explains it
        (``--strict-units``, or ``[calibration] strict_units = true``).
    printer : callable(str), optional
        Receives the progress lines (default: logged under ``calib.diagnosis.command`` and printed
        unless a command console is active, :func:`calib.logs.say`).
    resume : bool
        Continue the killed diagnosis whose history is in ``out`` (:mod:`calib.history`);
        refused when the data, config, rotor or noise model changed.
    noise : str, optional
        The noise model (``--noise``), replacing ``[calibration] noise`` of the config.
    facility : str, optional
        Where the campaign was measured (``--facility``), replacing ``[diagnosis] facility``.
    prefix : str
        What the progress lines start with (``calib demo`` runs the diagnosis under its own).
    history : bool
        Keep ``out/history`` (every model call and iteration as it happens).
    """
    from calib.report.diagnosis_report import write_diagnosis
    from calib.workflow import prepare

    if printer is None:
        def printer(line):
            say(log, line)
    if prefix != "[calib diagnose]":
        inner = printer

        def printer(line):
            inner(line.replace("[calib diagnose]", prefix, 1))

    cfg, src, base_dir = _read_config(config, rotor)
    if noise is not None:
        cfg["calibration"] = {**cfg.get("calibration", {}), "noise": noise}
    if facility is not None:
        cfg["diagnosis"] = {**cfg.get("diagnosis", {}), "facility": facility}
    is_fmu = isinstance(cfg.get("model"), dict) and cfg["model"].get("kind") == "fmu"
    dset, channels = _diagnosis_table(cfg.pop("diagnosis", {}), src, is_fmu)
    meas = read_measurements(data)
    for note in meas.notes:
        printer(f"[calib diagnose] {Path(data).name}: {note}")
    meas = _select_channels(meas, channels, src)
    wf = _workflow(cfg, list(meas.channels), src, base_dir)
    setup = prepare(wf)
    meas = _fill_conditions(meas, setup)
    set_up = statement(setup, wf, meas)
    for line in statement_lines(set_up):
        printer(f"[calib diagnose] set-up in force: {line}")
    grid = setup.grid(meas.conditions, prefix=prefix)
    hist = None
    if history or resume:
        hist = _open_history(out, rotor, data, config, force, setup, resume, printer, noise, facility)
    diag, unit_notes = _checked_diagnosis(setup, grid, meas, dset, hist, is_fmu=is_fmu, src=src, data=data,
                                          force=force or setup.force, strict=strict_units or setup.strict_units,
                                          printer=printer, prefix=prefix)
    diag.notes.extend(f"{key}: {text}" for key, text in unit_notes.items())
    diag.setup = set_up
    if diag.failure:
        printer(f"[calib diagnose] stopped early: {diag.failure}")
    paths = write_diagnosis(diag, out)
    if hist is not None:
        hist.event("finished", computed=hist.computed, replayed=hist.replayed, effect=diag.effect)
        printer(f"[calib diagnose] model calls: {hist.calls_sentence()}")
    printer(f"[calib diagnose] named: {diag.effect}" + (f" ({', '.join(diag.effects)})" if diag.effects else "")
            + (f"; model form: {', '.join(diag.model_form)}" if diag.model_form else "")
            + (f" between {' and '.join(diag.ambiguous)}" if diag.ambiguous else ""))
    printer(f"[calib diagnose] report: {paths['report']}")
    return diag


def _read_config(config: str | None, rotor: str | None) -> tuple[dict, str, Path]:
    """The tables of the config file with ``--rotor`` applied.

    Returns
    -------
    cfg : dict
        Table name -> table; always with a ``rotor`` table.
    src : str
        What errors name: the config file, else ``"calib diagnose"``.
    base_dir : Path
        Where relative paths of the config start (its folder, else the working folder).

    Raises
    ------
    InputError
        A table not in :data:`CONFIG_TABLES`, or no rotor from either source.
    """
    cfg = {}
    src = "calib diagnose"
    base_dir = Path.cwd()
    if config:
        path = Path(config)
        cfg = read_toml(path, "config file")
        unknown = [k for k in cfg if k not in CONFIG_TABLES]
        if unknown:
            raise InputError(f"unknown table(s) {', '.join(unknown)}; valid: {', '.join(CONFIG_TABLES)}", config,
                             field=unknown[0])
        src, base_dir = str(path), path.parent
    if rotor is not None:
        cfg["rotor"] = _rotor_table(rotor)
    if "rotor" not in cfg:
        raise InputError("no rotor: give --rotor NAME_OR_FILE or a [rotor] table in --config", src, field="rotor")
    return cfg, src, base_dir


def _workflow(cfg: dict, channels: list, src: str, base_dir: Path):
    """The one-stage workflow of the diagnosis (``channels`` measured), its tables checked as ``calib run``
    checks them (:func:`calib.workflow.schema.workflow_from_table`)."""
    from calib.workflow.schema import workflow_from_table

    wf = {"name": "diagnose", "rotor": cfg["rotor"], "grid": cfg.get("grid", DEFAULT_GRID),
          "stages": [{"name": "diagnose", "channels": channels}]}
    for key in ("model", "fluid", "calibration", "executor"):
        if key in cfg:
            wf[key] = cfg[key]
    return workflow_from_table(wf, src, base_dir, measured_elsewhere=True)


def _open_history(out: str, rotor: str | None, data: str, config: str | None, force: bool, setup, resume: bool,
                  printer, noise: str | None = None, facility: str | None = None):
    """Open (or, with ``resume``, continue) the history in ``out/history``, with the arguments and
    input digests that a resumed diagnosis must match (:func:`calib.history.open_history`)."""
    from calib.history import content_digest, open_history

    Path(out).mkdir(parents=True, exist_ok=True)
    # a rotor file by its absolute path, so that --resume works from any folder
    rotor_arg = str(Path(rotor).resolve()) if rotor is not None and Path(rotor).is_file() else rotor
    hist = open_history(out, {"command": "diagnose", "arguments": {
        "rotor": rotor_arg, "data": str(Path(data).resolve()),
        "config": str(Path(config).resolve()) if config else None, "force": bool(force), "noise": noise,
        "facility": facility},
        "inputs": {**diagnose_inputs(rotor_arg, data, config),
                   "rotor (geometry and polars)": content_digest(setup.rotor)}}, resume)
    hist.event("start", resumed=resume, records=hist.n_records)
    if resume:
        printer(f"[calib diagnose] resuming from {hist.folder}: {hist.n_records} model calls on record")
    return hist


def _checked_diagnosis(setup, grid, meas, dset, hist, *, is_fmu: bool, src: str, data: str, force: bool,
                       strict: bool, printer, prefix: str = "[calib diagnose]"):
    """The unit check, then :func:`calib.diagnosis.core.diagnose`, every model call recorded in ``hist``.

    An FMU's simulations run on an executor of ``[executor]``, closed at the end.

    Returns
    -------
    diag : Diagnosis
    unit_notes : dict
        What the unit check says for the report (:func:`_unit_check`).
    """
    from calib.logs import progress_line
    from calib.models.recorded_model import recorded

    family, executor, chunk = None, None, None
    if is_fmu:
        family, executor = _fmu_family(setup, grid, list(meas.channels), dset, src)
        chunk = max(int(executor.workers), 1)   # a kill loses at most one chunk of simulations

    def wrap(model, label):
        return recorded(model, hist, label, chunk, progress=progress_line)

    try:
        unit_notes = _unit_check(setup, family, meas, wrap, data, force, strict, printer, prefix)
        diag = diagnose(setup.rotor, meas, grid, setup.settings, setup.calibration, dset,
                        progress=lambda s: printer(f"[calib diagnose] {s}"), rotor_source=setup.rotor_spec,
                        wrap=wrap, fit_progress=lambda done, total: progress_line(done, total, "candidate fits"),
                        family=family,
                        on_iteration=None if hist is None else (lambda rec: hist.event("iteration", **rec)))
    finally:
        if executor is not None:
            executor.close()
    return diag, unit_notes


def _diagnosis_table(table, src: str, is_fmu: bool):
    """The DiagnosisSettings and channel list (None: every measured channel) of ``[diagnosis]``."""
    if not is_fmu:
        return diagnosis_settings(table, src)
    # an FMU's candidates are its mapped parameters: their names are checked with the model
    cands = table.get("candidates") if isinstance(table, dict) else None
    return diagnosis_settings(table, src, valid=tuple(cands) if isinstance(cands, list) else ())


def _fill_conditions(meas, setup):
    """Air density and yaw of a table without those columns from the config (``[fluid] density``,
    ``[model] yaw``), as ``calib run`` fills them."""
    import dataclasses

    import numpy as np

    declared = meas.metadata.get("units", {})
    fill = {}
    if "air_density" not in declared:
        fill["air_density"] = np.full(meas.n_points, float(setup.density))
    if "yaw" not in declared and setup.yaw != 0.0:
        fill["yaw"] = np.full(meas.n_points, float(setup.yaw))
    if not fill:
        return meas
    return dataclasses.replace(meas, conditions=dataclasses.replace(meas.conditions, **fill))


def _select_channels(meas, channels, src: str):
    """``meas`` restricted to the ``[diagnosis] channels`` (all of them when None)."""
    if channels is None:
        return meas
    missing = [c for c in channels if c not in meas.channels]
    if missing:
        raise InputError(f"channel(s) {', '.join(missing)} not in the data file {meas.source} (its channels: "
                         f"{', '.join(meas.channels)})", src, field="diagnosis.channels")
    return meas.select_channels(channels)


def _unit_check(setup, family, meas, wrap, data: str, force: bool, strict: bool, printer,
                prefix: str = "[calib diagnose]") -> dict:
    """The unit check of ``calib run`` on the nominal model (same messages); its notes for the report.

    Raises
    ------
    InputError
        When a unit factor explains the data and not ``force`` (the file, the channel or
        condition and the suspected factor named).
    """
    import numpy as np

    from calib.checks.unit_check import apply_unit_check

    # the nominal model: an FMU family's own, else the native BEM with its nuisance parameters at nominal
    model = wrap(family.nominal_model() if family is not None else setup.model(None, list(meas.channels)),
                 "unit check")
    p = np.array([q.nominal for q in model.parameters], float)
    _, notes = apply_unit_check(model, p, meas, sigma=setup.calibration.sigma, force=force,
                                strict=strict, source=str(data), printer=printer,
                                prefix=prefix, model_units=setup.model_units())
    return notes


def _fmu_family(setup, grid, channels: list, dset, src: str):
    """The FMU family of a ``[model] kind = "fmu"`` config and the executor its simulations run on."""
    from calib.diagnosis.fmu import FmuFamily
    import dataclasses

    from calib.models.from_config import executor_of, fmu_model

    executor = executor_of(setup.executor, src)

    def build(parameters, corrections, probe_channels=None):
        table = dataclasses.replace(setup.model_table, parameters=tuple(parameters), corrections=bool(corrections))
        return fmu_model(table, setup.rotor_spec, probe_channels or channels, src, setup.base_dir, grid=grid,
                         executor=executor)

    try:
        family = FmuFamily(build, dset.candidates)
        dset.validate(src, "diagnosis.", valid=family.names)
    except BaseException:
        executor.close()
        raise
    return family, executor


def add_diagnose_arguments(parser) -> None:
    """The arguments of ``calib diagnose`` but ``--rotor`` (defined by :mod:`calib.cli`)."""
    parser.add_argument("--data", default=None, help="measurement CSV (layout: workflows/README.md); required "
                        "unless --resume")
    parser.add_argument("--out", default=None, help="output folder (required unless --resume DIR)")
    parser.add_argument("--config", default=None, help="TOML with [rotor], [model], [fluid], [grid], [calibration] "
                        "tables of the workflow schema and a [diagnosis] table (candidates, candidate_options, "
                        "max_effects, significance, ambiguity_bic, ambiguity_pattern, model_form_tolerance, recalibrate, "
                        "facility, cross_section, channels)")
    parser.add_argument("--resume", metavar="DIR", default=None, help="continue the killed diagnosis whose output "
                        "folder is DIR with the arguments it started with: model calls on record in DIR/history are "
                        "read back, not computed again; refused if the data, config or rotor changed")
    parser.add_argument("--force", action="store_true", help="diagnose even when the unit check suspects a unit "
                        "mistake in the measurements (the report says so); a resumed diagnosis keeps the --force "
                        "it started with")
    parser.add_argument("--strict-units", action="store_true", help="also stop when the nominal model misses the "
                        "data and no unit factor explains it (default: a loud warning, then diagnose)")
    from calib.calibration.settings import NOISE_MODES
    parser.add_argument("--noise", choices=NOISE_MODES, default=None, help="the noise model, as [calibration] noise "
                        "(which it replaces): 'ml' estimates one σ per channel from the fit, for a table without "
                        "_sigma columns; default: the config's, else 'known' (the _sigma columns)")
    from calib.diagnosis.settings import FACILITIES
    parser.add_argument("--facility", choices=FACILITIES[1:], default=None, help="where the campaign was measured, "
                        "as [diagnosis] facility (which it replaces): in the 'field' wind-tunnel blockage is not a "
                        "candidate; default: the config's, else unstated (every candidate tried)")
    add_output_arguments(parser, "also print every model call (the log file DIR/calib.log always has them)")


def diagnose_from_args(args) -> int:
    """``calib diagnose`` from parsed arguments; returns the exit code."""
    from calib.logs import command_logging

    rotor, data, config, out = args.rotor, args.data, args.config, args.out
    force = bool(getattr(args, "force", False))
    noise = getattr(args, "noise", None)
    facility = getattr(args, "facility", None)
    if args.resume is not None:
        if out is not None and Path(out).resolve() != Path(args.resume).resolve():
            raise InputError(f"--out {out} and --resume {args.resume} name different folders; give one",
                             "calib diagnose", field="--out")
        out = args.resume
        manifest = Path(out) / "history" / "manifest.json"
        if not manifest.is_file():
            raise InputError(f"nothing to resume: no history/manifest.json in {out}", str(out), field="--resume")
        recorded_args = json.loads(manifest.read_text()).get("arguments", {})
        rotor = rotor if rotor is not None else recorded_args.get("rotor")
        data = data if data is not None else recorded_args.get("data")
        config = config if config is not None else recorded_args.get("config")
        force = force or bool(recorded_args.get("force", False))
        noise = noise if noise is not None else recorded_args.get("noise")
        facility = facility if facility is not None else recorded_args.get("facility")
    if data is None or out is None:
        raise InputError("give --data FILE and --out DIR (or --resume DIR)", "calib diagnose",
                         field="--data" if data is None else "--out")
    with command_logging(out, args.verbose, args.quiet):
        try:
            run_diagnose(rotor, data, out, config, resume=args.resume is not None, history=not args.no_history,
                         force=force, strict_units=bool(getattr(args, "strict_units", False)), noise=noise,
                         facility=facility)
        except CalibError as exc:      # printed on stderr by the caller; the log file keeps it too
            log.debug(f"calib: error: {exc}", exc_info=True)
            raise
    return 0
