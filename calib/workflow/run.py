"""Running a workflow (``calib run FILE --out DIR``): its stages, diagnosis and validation, results,
figures and report, with history and resume; the command-line entry."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
import time
from pathlib import Path

import numpy as np

from calib.calibration.calibrator import Calibrator
from calib.checks.unit_check import apply_unit_check
from calib.errors import CalibError, InputError
from calib.logs import add_output_arguments, say
from calib.measurements import sha256_of, synthesize
from calib.models.bem_model import BemModel
from calib.report.setup_statement import statement, statement_html, statement_lines
from calib.types import nominal_vector
from calib.workflow.schema import load_workflow
from calib.workflow.setup import StageOutcome, measurements_of, prepare, run_inputs, synthetic_conditions
from calib.workflow.sections import Stage
from calib.workflow.truth import smooth_field, truth_checks, truth_model

log = logging.getLogger("calib.workflow")


def run_workflow(path: str | Path, out_dir: str | Path, progress: bool = True,
                 force: bool = False, resume: bool = False, history: bool = True,
                 strict_units: bool = False, noise: str | None = None) -> list[StageOutcome]:
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
        Calibrate even when the unit check (:func:`calib.checks.unit_check.apply_unit_check`) finds
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
    noise : str, optional
        The noise model (``calib run --noise``), replacing the workflow's ``[calibration] noise``.
    """
    workflow = load_workflow(path)
    src = workflow.source
    if noise is not None:
        workflow = workflow.with_noise(noise)
    # everything the settings can get wrong is found here, before any data is read
    setup = prepare(workflow)
    force = setup.force or force
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for note in setup.notes:
        say(log, f"[calib run] set-up: {note}", progress)
    hist = None
    if history or resume:
        from calib.history import content_digest, open_history
        inputs = {**run_inputs(workflow), "rotor (geometry and polars)": content_digest(setup.rotor)
                  if setup.rotor is not None else None}
        hist = open_history(out, {"command": "run", "workflow": str(Path(src).resolve()), "noise": noise,
                                  "inputs": inputs}, resume)
        hist.event("start", resumed=resume, records=hist.n_records)
        if resume:
            say(log, f"[calib run] resuming from {hist.folder}: {hist.n_records} model calls on record", progress)

    from calib.models.from_config import executor_of
    executor = executor_of(setup.executor, src)
    try:
        outcomes = _run(workflow, setup, out, executor, progress, force, hist, strict_units)
    finally:
        executor.close()
    if hist is not None:
        hist.event("finished", computed=hist.computed, replayed=hist.replayed)
        say(log, f"[calib run] model calls: {hist.calls_sentence()}", progress)
    return outcomes


def _run(workflow, setup, out, executor, progress, force, hist=None, strict=False):
    """The workflow's steps: its measurements, the diagnosis, each stage (calibration, validation, results,
    figures) and the report; returns the stages' :class:`StageOutcome`."""
    from calib.diagnosis import in_workflow
    from calib.report.html import write_report

    def echo(line):
        say(log, line, progress)

    # an FMU's calls are recorded in chunks of points (a kill loses at most one chunk of simulations)
    chunk = max(int(executor.workers if executor is not None else 1), 1) if setup.is_fmu else None
    run = _Run(workflow, setup, out, executor, hist, echo, chunk)
    run.measurements(progress, force, strict)
    if setup.diagnosis is not None:   # the diagnosis first; its named effects join every stage
        run.effects, run.diag = in_workflow.run_diagnosis(setup, run.meas, run.grid, out, executor, echo, hist)
    outcomes = [run.stage(k, stage) for k, stage in enumerate(workflow.stages)]
    intro = workflow.description
    if run.truth_p is not None:
        intro += " Measurements are synthetic: a truth model with a smooth correction field sampled on a fine " \
                 "grid (not in the span of the calibration's shape functions) plus seeded Gaussian noise."
    from calib.workflow import validation
    sections = [statement_html(run.set_up)] + ([validation.section_html(run.diag, run.validations)]
                                              if (run.diag or run.validations) else [])
    report = write_report(out / "report.html", title=f"calib: {workflow.name}", sections=sections,
                          results={o.name: o.result for o in outcomes},
                          figures={o.name: o.figures for o in outcomes}, intro=intro,
                          extra_figures=run.study_figures(outcomes),
                          checks={o.name: o.result.provenance.checks for o in outcomes})
    echo(f"[calib run] report: {report}")
    return outcomes


class _Run:
    """One run of a workflow: what its steps share (measurements, grid, named effects, validations)."""

    def __init__(self, workflow, setup, out, executor, hist, echo, chunk):
        self.workflow, self.setup, self.out, self.executor, self.hist, self.echo, self.chunk = \
            workflow, setup, out, executor, hist, echo, chunk
        self.src = workflow.source
        self.effects, self.diag, self.validations = [], None, {}
        self.unit_notes, self.truth_p = {}, None

    def measurements(self, progress, force, strict) -> None:
        """The measured table (with the set-up's density and yaw, checked against the model's units) or the
        synthetic one of ``[truth]``; the correction grid; the set-up in force."""
        from calib.logs import progress_line
        from calib.models.recorded_model import recorded

        workflow, setup, echo, src = self.workflow, self.setup, self.echo, self.src
        all_channels = setup.channels
        t0 = time.perf_counter()
        if workflow.measurements is not None:
            file = Path(workflow.base_dir) / workflow.measurements.file
            meas = measurements_of(workflow, all_channels)
            if "air_density" not in meas.metadata.get("units", {}):
                meas = dataclasses.replace(meas, conditions=dataclasses.replace(
                    meas.conditions, air_density=np.full(meas.n_points, setup.density)))
            if "yaw" not in meas.metadata.get("units", {}) and setup.yaw != 0.0:
                meas = dataclasses.replace(meas, conditions=dataclasses.replace(
                    meas.conditions, yaw=np.full(meas.n_points, setup.yaw)))
            for note in meas.notes:
                echo(f"[calib run] {file.name}: {note}")
            self.set_up = statement(setup, workflow, meas)
            for line in statement_lines(self.set_up):
                echo(f"[calib run] set-up in force: {line}")
            self.grid = setup.grid(meas.conditions, progress)
            check_model = recorded(setup.model(self.grid, all_channels, self.executor), self.hist, "unit check",
                                   self.chunk, progress_line)
            _, self.unit_notes = apply_unit_check(check_model, nominal_vector(check_model.parameters), meas,
                                                  sigma=setup.calibration.sigma, force=force,
                                                  strict=strict or setup.strict_units, source=str(file),
                                                  printer=echo, model_units=setup.model_units())
        else:
            cond = synthetic_conditions(workflow.conditions, setup.rotor, setup.density, setup.yaw)
            self.grid = setup.grid(cond, progress)
            rel = workflow.noise.relative
            missing = [c for c in all_channels if c not in rel]
            if missing:
                raise InputError(f"no noise level for channel(s) {', '.join(missing)}", src,
                                 field=f"noise.relative.{missing[0]}")
            self.set_up = statement(setup, workflow)
            for line in statement_lines(self.set_up):
                echo(f"[calib run] set-up in force: {line}")
            tmodel, self.truth_p = truth_model(setup.rotor, all_channels, setup.settings, workflow.truth,
                                               setup.nuisance)
            meas = synthesize(tmodel, self.truth_p, cond, relative_sigma={c: float(rel[c]) for c in all_channels},
                              channels=all_channels, seed=workflow.noise.seed, source=f"synthetic ({src})")
            meas.write_csv(self.out / "measurements.csv")
        self.meas = meas
        echo(f"[calib run] {workflow.name}: {setup.model_name()}, {meas.n_points} operating points, "
             f"channels {', '.join(meas.channels)} ({time.perf_counter() - t0:.1f} s)")

    def callback(self, name: str):
        """The calibration's progress: to the history, and the steps a user follows to the terminal."""
        hist, echo = self.hist, self.echo

        def callback(rec):
            if hist is not None:
                hist.event("iteration", run=name, **rec)
            if rec.get("stage") == "relinearize":
                echo(f"[calib run] {name}: re-linearization {rec.get('iteration')}: "
                     f"{rec.get('n_retained')} retained, cost {rec.get('cost', float('nan')):.4g}")
            elif rec.get("stage") == "map_done":
                echo(f"[calib run] {name}: MAP estimate {rec['status']} after {rec['iterations']} iteration(s), "
                     f"cost {rec['cost']:.4g}; the data determine {rec['data_beat_prior']} direction(s) better "
                     "than the prior")
            elif rec.get("stage") == "second_start":
                echo(f"[calib run] {name}: χ² {rec['chi2']:.4g} over {rec['dof']} rejects the stated noise "
                     f"(p = {rec['p_value']:.2g}): the automatic choice starts again from the prior limit's count")
            elif rec.get("stage") == "second_start_done":
                echo(f"[calib run] {name}: {rec['first_retained']} θ from nominal ({rec['first_status']}), "
                     f"{rec['second_retained']} θ from the limit ({rec['second_status']}); kept the "
                     f"{'second' if rec['second_kept'] else 'first'}")
            else:
                log.debug("%s: %s", name, ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}"
                                                      for k, v in rec.items() if k != "qp"))
        return callback

    def stage(self, k: int, stage: Stage) -> StageOutcome:
        """One stage: calibrate, validate, write its result and figures, say what it found."""
        from calib.diagnosis import in_workflow
        from calib.logs import progress_line
        from calib.models.recorded_model import recorded
        from calib.report.figures import write_figures
        from calib.workflow import validation

        workflow, setup, echo, src, grid, meas = self.workflow, self.setup, self.echo, self.src, self.grid, self.meas
        name, channels = stage.name, list(stage.channels)
        raw_model = setup.model(grid, channels, self.executor, self.effects)
        model = recorded(raw_model, self.hist, f"stage {k + 1}: {name}", self.chunk, progress_line)
        # a stage's retain mode was checked with its table (stages[k].retain)
        st = dataclasses.replace(setup.calibration, retain=stage.retain or setup.calibration.retain)
        cal = Calibrator(model, meas.select_channels(channels), st, self.callback(name), name=name)
        t_cal = time.perf_counter()
        res = cal.run()
        t_cal = time.perf_counter() - t_cal
        res.provenance.inputs[src] = sha256_of(src)
        res.provenance.inputs["workflow"] = workflow.name
        res.provenance.checks.update(self.unit_notes)
        res.provenance.checks.update(_fault_checks(raw_model))
        if self.truth_p is not None:
            res.provenance.checks.update(truth_checks(model, res, workflow.truth))
        if self.diag is not None:
            res.provenance.checks["diagnosis"] = in_workflow.diagnosis_sentence(self.diag)
        if setup.validation is not None:
            kind = "leave-one-out" if setup.validation.split == "one" else "band split"
            val = validation.leave_one_out(
                lambda _c=tuple(channels): setup.model(grid, list(_c), self.executor, self.effects),
                meas.select_channels(channels), st, setup.validation,
                progress=lambda line, _n=name, _k=kind: echo(f"[calib run] {_n}: {_k}: {line}"))
            self.validations[name] = val
            res.provenance.checks.update({f"{kind} ({c})": val.sentence(c) for c in val.channels()})
        stage_dir = self.out / f"stage{k + 1}_{''.join(ch if ch.isalnum() else '_' for ch in name)}"
        stage_dir.mkdir(exist_ok=True)
        t_rep = time.perf_counter()
        res.save(stage_dir)
        if name in self.validations:
            validation.write_validation(self.validations[name], stage_dir)
        truth = (lambda a, e, _b=workflow.truth.bumps: smooth_field(_b, a, e)) if self.truth_p is not None else None
        figs = write_figures(res, stage_dir, truth=truth, progress=lambda line: echo(f"[calib run] {line}"))
        t_rep = time.perf_counter() - t_rep
        if self.hist is not None:
            self.hist.event("stage_done", run=name, folder=stage_dir.name, status=res.estimate.status,
                            model_evaluations=res.fit.failures.get("model_evaluations"),
                            model_jacobians=res.fit.failures.get("model_jacobians"))
        kept = (f"the data beat the prior in {res.n_retained} of {res.n_params} directions" if res.estimator == "map"
                else f"{res.n_retained} of {res.n_params} retained")
        echo(f"[calib run] {name}: {res.summary().splitlines()[0].split(': ', 1)[-1]}; {kept}; "
             f"chi2/dof {res.chi2_per_dof_before:.3g} -> {res.chi2_per_dof_after:.3g} against {res.noise_words()}; "
             f"calibration {t_cal:.1f} s, figures {t_rep:.1f} s; results in {stage_dir}")
        for label, text in res.provenance.checks.items():
            echo(f"[calib run] {name}: {label}: {text}")
        return StageOutcome(name, res, figs, stage_dir)

    def study_figures(self, outcomes) -> dict:
        """The figures across stages: the singular-value spectra, and with measured data and a diagnosis or a
        validation the loads against wind speed and the informed eigenshapes."""
        from calib.report.figures import save_figure
        from calib.report.spectrum_figures import plot_spectra
        from calib.workflow import validation

        workflow, out, extra = self.workflow, self.out, {}
        if len(outcomes) > 1:
            fig = plot_spectra({o.name: o.result for o in outcomes})
            extra["singular_value_spectra"] = save_figure(fig, out, "singular_value_spectra")
        if workflow.measurements is not None and (self.diag is not None or self.validations):
            rotor_ch = [c for c in self.setup.channels if "@" not in c]
            span_ch = [c for c in self.setup.channels if c.startswith("cn@")]
            for key, chans, what in (("loads_vs_wind_speed", rotor_ch, "rotor loads"),
                                     ("cn_vs_wind_speed", span_ch, "normal-force coefficient at the pressure taps")):
                if chans:
                    fig = validation.campaign_figure(self.setup, self.meas, self.grid, outcomes, self.diag,
                                                     self.validations, self.effects, chans,
                                                     f"{workflow.name}: {what}, measured and modelled", self.executor)
                    extra[key] = save_figure(fig, out, key)
            for k, o in enumerate(outcomes):
                fig = validation.informed_eigenshapes(o.result)
                if fig is not None:
                    extra[f"informed_eigenshapes_stage{k + 1}"] = save_figure(
                        fig, out, f"informed_eigenshapes_stage{k + 1}")
        return extra


def _fault_checks(model) -> dict[str, str]:
    """An FMU stage's report lines on its simulations' faults: the timeout in force, the points
    quarantined and those with an error status (:func:`calib.fmu.faults.fault_sentences`);
    nothing for the native BEM."""

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
    from calib.calibration.settings import NOISE_MODES
    parser.add_argument("--noise", choices=NOISE_MODES, default=None, help="the noise model, replacing the "
                        "workflow's [calibration] noise ('ml': one σ per channel estimated from the fit, for a table "
                        "without _sigma columns)")
    add_output_arguments(parser, "also print every optimizer iteration and model call (the log file "
                         "DIR/calib.log always has them)")


def run_from_args(args) -> int:
    """``calib run`` from parsed arguments (see :func:`add_run_arguments`); returns the exit code."""
    from calib.logs import command_logging

    out, file = args.out, args.file
    noise = getattr(args, "noise", None)
    if args.resume is not None:
        if out is not None and Path(out).resolve() != Path(args.resume).resolve():
            raise InputError(f"--out {out} and --resume {args.resume} name different folders; give one", "calib run",
                             field="--out")
        out = args.resume
        manifest = Path(out) / "history" / "manifest.json"
        if file is None or noise is None:
            if not manifest.is_file():
                raise InputError(f"nothing to resume: no history/manifest.json in {out}", str(out), field="--resume")
            import json
            recorded = json.loads(manifest.read_text())
            file = file if file is not None else recorded.get("workflow")
            noise = noise if noise is not None else recorded.get("noise")
    if file is None or out is None:
        raise InputError("give a workflow file and --out DIR (or --resume DIR)", "calib run",
                         field="file" if file is None else "--out")
    with command_logging(out, args.verbose, args.quiet):
        try:
            run_workflow(file, out, force=args.force, resume=args.resume is not None, history=not args.no_history,
                         strict_units=getattr(args, "strict_units", False), noise=noise)
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


__all__ = ["main", "run_workflow"]
