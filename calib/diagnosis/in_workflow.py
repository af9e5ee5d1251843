"""The diagnosis inside a workflow (``[diagnosis]`` of ``calib run``): its settings table, the run
that writes ``DIR/diagnosis/``, and what the stages take from it (the named effects' specs, one
sentence for each stage's result).

A workflow with a ``[diagnosis]`` table runs :func:`calib.diagnosis.core.diagnose` on the
measurements before its stages; every effect it names joins each stage's model with its
*default* nominal value and prior (the stage re-estimates it with the correction field, so
a validation fold never sees a value fitted on its held-out point).
"""

from __future__ import annotations

import dataclasses
from typing import Callable

from calib.config import Key, names_list, settings_from_table
from calib.diagnosis.settings import NAMEABLE, DiagnosisSettings
from calib.measurements import Measurements

#: [diagnosis] keys of a workflow: the DiagnosisSettings fields (their types checked by its validate()), plus
#: the channels it uses.
DIAGNOSIS_SCHEMA = {**{f.name: Key(object) for f in dataclasses.fields(DiagnosisSettings)},
                    "channels": Key(list, check=lambda v: None if v and names_list(v) is None
                                    else "must be a non-empty array of channel names")}


def diagnosis_settings(table: dict, source: str, valid=NAMEABLE) -> tuple[DiagnosisSettings, list | None]:
    """The :class:`DiagnosisSettings` and channel list of a ``[diagnosis]`` table (of a workflow
    or of ``calib diagnose --config``); ``valid``: the candidate names of the model family."""
    # the keys are checked here, the values' types by validate()
    dset = settings_from_table(DiagnosisSettings, table, "diagnosis", source, DIAGNOSIS_SCHEMA)
    channels = table.get("channels")
    return dset.validate(source, "diagnosis.", valid=valid), channels




def named_effect_specs(diag, skip=()) -> list[dict]:
    """Specs of the effects a diagnosis named, with their default (not fitted) nominal values.

    Parameters
    ----------
    diag : calib.diagnosis.core.Diagnosis
    skip : sequence of str
        Effects the stage models already carry (the workflow's nuisance parameters, e.g.
        ``pitch_offset``): a named one is free in every stage already and is not added twice.

    Returns
    -------
    list of dict
        ``{"name": ..., "options": {...}}`` per named effect, in naming order (the variant
        the diagnosis preferred is kept).
    """
    specs = []
    for rnd in diag.rounds:
        verdict = rnd["verdict"]
        if verdict in ("none", "ambiguous", "failed"):
            break
        best = next(f for f in rnd["candidates"] if f.effect == verdict and f.significant)
        if best.effect not in skip:
            specs.append(dict(best.spec))
    return specs




def run_diagnosis(setup, measurements: Measurements, grid, out_dir, executor=None,
                  echo: Callable[[str], None] = print, history=None):
    """The ``[diagnosis]`` step of a workflow: diagnose, write ``DIR/diagnosis/``, return the
    named effects' specs (default nominal values; first the facility's known corrections, a stated
    cross-section's blockage) and the :class:`~calib.diagnosis.core.Diagnosis`.

    With ``history`` (:mod:`calib.history`), every model call and optimizer iteration of the
    diagnosis is recorded, so ``calib run --resume`` replays it instead of computing it again.
    """
    from pathlib import Path

    from calib.diagnosis.bem_family import facility_effects
    from calib.diagnosis.core import diagnose
    from calib.report.diagnosis_report import write_diagnosis

    dset, channels = setup.diagnosis
    meas = measurements.select_channels(channels) if channels else measurements
    wrap = on_iteration = None
    if history is not None:
        from calib.models.recorded_model import recorded

        wrap = lambda model, label: recorded(model, history, f"diagnosis: {label}")  # noqa: E731
        on_iteration = lambda rec: history.event("iteration", **{"run": "diagnosis", **rec})  # noqa: E731
    diag = diagnose(setup.rotor, meas, grid, setup.settings, setup.calibration, dset, executor=None,
                    progress=lambda line: echo(f"[calib run] diagnosis: {line}"), rotor_source=setup.rotor_spec,
                    wrap=wrap, on_iteration=on_iteration)
    paths = write_diagnosis(diag, Path(out_dir) / "diagnosis")
    # the facility's known corrections (a stated cross-section) join every stage's model too
    specs = [e.spec() for e in facility_effects(dset, setup.rotor)] + named_effect_specs(diag, skip=setup.nuisance)
    echo(f"[calib run] diagnosis: named {diag.effect}" + (f" ({', '.join(diag.effects)})" if diag.effects else "")
         + (f"; model form: {', '.join(diag.model_form)}" if diag.model_form else "")
         + f"; report {paths['report']}")
    return specs, diag




def diagnosis_sentence(diag) -> str:
    """One line for a result's checks: what the diagnosis named, with its evidence."""
    failed = f"; stopped early: {diag.failure}" if diag.failure else ""
    if not diag.rounds:
        return f"no candidate could be fitted; named {diag.effect}{failed}"
    reasons = "; ".join(r["reason"] for r in diag.rounds)
    added = ", ".join(diag.effects) if diag.effects else "nothing"
    gap = (f"{diag.before['chi2_per_dof']:.3g} nominal -> {diag.with_effects['chi2_per_dof']:.3g} with the effect(s) "
           "at their fitted values" if diag.effects else f"{diag.before['chi2_per_dof']:.3g} nominal, no effect added")
    between = f" between {' and '.join(diag.ambiguous)}" if diag.ambiguous else ""
    return (f"named {diag.effect}{between} (free parameters of this model: {added}); {reasons}; χ²/dof "
            f"{gap}{failed} (see diagnosis/report.html)")
