"""The diagnosis: find where model and measurements disagree, name the missing
effect, add it, show the gap shrink (docs/theory.md, Diagnosis).

This module runs the steps (:func:`diagnose`) and the naming rounds of step 3. Beside it live
the settings (:mod:`calib.diagnosis.settings`), the result (:mod:`calib.diagnosis.result`), the
figures of merit (:mod:`calib.diagnosis.figures_of_merit`), the candidates of the native BEM
(:mod:`calib.diagnosis.bem_family`) and their fitted parameters
(:mod:`calib.diagnosis.candidate_parameters`), the statistics that rank candidates
(:mod:`calib.diagnosis.ranking`) and the verdict of a naming round (:mod:`calib.diagnosis.verdict`).

Steps
-----
1. **Find**: the nominal model's whitened residuals r = (z − y)/σ; the χ² test (χ²/N and its
   p-value) says whether the model is consistent with the noise; per channel and against
   tip-speed ratio, pitch and wind speed the residuals say where it is not.
2. **Localize**: the SVD calibration of the correction field (:class:`calib.calibration.Calibrator`,
   automatic truncation) says which (α, η) region of the polars would have to change; with
   ``noise = "ml"`` it also gives the noise σ the later steps use.
3. **Name**: every candidate effect of :data:`calib.effects.EFFECTS` (but the correction field)
   is switched into the model on its own and fitted by maximum likelihood (all its few
   parameters free); an effect with several model forms (rotational augmentation: Snel,
   Du & Selig, Chaviaropoulos & Hansen) enters once per form, and its best form names it. Candidates are compared with the model without them by

   - the likelihood-ratio statistic Λ = χ²_base − χ²_candidate, χ²(k)-distributed with k the
     candidate's parameter count when the candidate adds nothing (Wilks 1938); significant
     when its p-value is below ``significance`` divided by the number of candidates
     (Bonferroni);
   - the Bayesian information criterion BIC = χ² + k ln N and the weights
     w ∝ exp(−½ BIC) over the candidates and "none" (Schwarz 1978; Burnham & Anderson 2002);
   - the agreement of the candidate's change of the outputs with the localized correction's
     change (correlation of the two whitened output changes): an effect that explains the data
     moves the outputs the way the free correction field does.

   The best significant candidate is named when no other significant candidate is within
   ``ambiguity_bic`` of its BIC; otherwise the result is ``ambiguous`` and names both. With
   nothing significant the result is ``none``. After naming one effect, it is added with its
   fitted parameters and, while the model is still inconsistent with the noise (χ² test at
   ``significance``), the remaining candidates are tried on top (up to ``max_effects``).

   A fitted parameter within :data:`AT_BOUND_TOLERANCE` (10⁻³) of its scale of a bound is
   **at bound** (:func:`bound_side`): the candidate table and the verdict say so, since its
   value is the bound the data push against, not an estimate. A named effect joins the next
   round with its fitted values clipped into their bounds (an estimate on a bound may end a
   few ulp past it). A round that fails (a :class:`~calib.errors.CalibError`) is recorded
   with verdict ``failed``; the naming stops there and the earlier rounds' findings stand
   (``Diagnosis.failure`` says what failed), as when the recalibration fails.
4. **Add** the named effect(s) with their fitted parameters; **recalibrate** the correction
   field on top for what remains.
5. **Show** χ²/dof and per-channel RMS before (nominal), with the named effect(s), and after
   the recalibration.

References
----------
S.S. Wilks, The large-sample distribution of the likelihood ratio for testing composite
hypotheses, Ann. Math. Stat. 9 (1938) 60-62.
G. Schwarz, Estimating the dimension of a model, Ann. Stat. 6 (1978) 461-464.
K.P. Burnham, D.R. Anderson, Model Selection and Multimodel Inference, 2nd ed., Springer (2002).
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models from
rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.diagnosis.bem_family import BemFamily
from calib.diagnosis.candidate_parameters import STUCK_TOLERANCE, _parameter_records, away_start
from calib.diagnosis.figures_of_merit import effect_size, find, gap
from calib.diagnosis.ranking import likelihood_ratio, pattern_agreement
from calib.diagnosis.result import CandidateFit, Diagnosis
from calib.diagnosis.settings import DiagnosisSettings
from calib.diagnosis.verdict import _separation_of, judge_round
from calib.errors import CalibError, InputError
from calib.measurements import Measurements
from calib.words import p_is

# moved to the step modules, importable from here as before
from calib.diagnosis.bem_family import PROBE_STATIONS, _fixed_effect  # noqa: F401
from calib.diagnosis.candidate_parameters import AT_BOUND_TOLERANCE, bound_side  # noqa: F401
from calib.diagnosis.figures_of_merit import EFFECT_SIZE_USABLE  # noqa: F401
from calib.diagnosis.settings import MODEL_FORM_TOLERANCE, NAMEABLE  # noqa: F401
from calib.diagnosis.verdict import _bound_suffix  # noqa: F401

#: Noise models whose σ the calibration estimates from the residuals (no global test against it).
ESTIMATED_NOISE = ("ml", "relative_ml")

#: Relative χ² increase a recalibration may show before it is rejected (round-off of the sums) [-].
RECALIBRATION_SLACK = 1e-9


def diagnose(rotor, measurements: Measurements, grid: CorrectionGrid, settings: BemSettings | None = None,
             calibration: CalibrationSettings | None = None, diagnosis: DiagnosisSettings | None = None,
             executor=None, progress: Callable[[str], None] | None = None, rotor_source: dict | None = None,
             wrap: Callable | None = None, fit_progress: Callable[[int, int], None] | None = None,
             family=None, on_iteration: Callable[[dict], None] | None = None) -> Diagnosis:
    """Run the diagnosis on the native BEM (see the module notes).

    Parameters
    ----------
    rotor : Rotor
    measurements : Measurements
        Channels of the native BEM; σ from ``_sigma`` columns, ``calibration.sigma``, or
        estimated (``calibration.noise = "ml"``) by the localization step.
    grid : CorrectionGrid
        Nodes of the correction field (localization and recalibration).
    settings : BemSettings, optional
    calibration : CalibrationSettings, optional
        For the localization and the recalibration (the candidate fits retain every parameter).
    diagnosis : DiagnosisSettings, optional
    executor : Executor, optional
        Runs the candidate fits (:mod:`calib.executors`; default serial).
    progress : callable(str), optional
        Receives one line per step.
    wrap : callable(model, label) -> model, optional
        Applied to every model the diagnosis calibrates or evaluates (e.g.
        :func:`calib.history.recorded`, which records each call and answers it on resume).
    fit_progress : callable(done, total), optional
        Called as the candidate fits of a round finish.
    family : optional
        The models to calibrate (default :class:`BemFamily` of ``rotor``, ``grid``,
        ``settings``); e.g. :class:`calib.diagnosis.fmu.FmuFamily` for an FMU.
    on_iteration : callable(dict), optional
        Receives every optimizer iteration record of the localization and the recalibration
        (:class:`~calib.calibration.Calibrator` records with ``run`` added).

    Returns
    -------
    Diagnosis
        With ``failure`` non-empty when a naming round or the recalibration failed: the
        rounds before it, and the gap with the effects they named, are still reported.
    """
    t0 = time.perf_counter()
    settings = settings or BemSettings()
    channels = list(measurements.channels)
    family = family or BemFamily(rotor, channels, grid, settings, rotor_source)
    cal, dset = _fit_settings(calibration, diagnosis, family)
    say = progress or (lambda s: None)
    wrap = wrap or (lambda model, label: model)

    # 2. localize (first: with noise = "ml" it gives the σ every later step uses)
    loc, meas = _localize(family, measurements, cal, wrap, on_iteration, say)
    sigma = loc.sigma

    # 1. find
    y0, before, findings = _find_disagreement(family, meas, wrap, say, loc.noise_words())

    # 3. name, up to max_effects rounds (a round that fails ends the naming; earlier rounds stand),
    # against the noise plus the model-form tolerance
    namer = _name_effects(family, meas, y0, before, loc.model_after, cal, dset, executor, wrap, fit_progress, say)
    effect, effects_named = namer.verdict()
    n_fit = family.n_parameters(namer.base_effects)
    with_effects = gap(meas.values, namer.base_values, sigma, channels, n_fit)

    # 4. add + recalibrate the field on top
    recal = _recalibrate(family, namer, meas, cal, dset, wrap, on_iteration, say, effects_named)
    y_after = None if recal is None else recal.model_after
    after = with_effects if recal is None else gap(meas.values, y_after, sigma, channels, n_fit + recal.n_retained)
    say(f"show: χ²/dof {before['chi2_per_dof']:.3g} -> {with_effects['chi2_per_dof']:.3g} with "
        f"{', '.join(effects_named) or 'no effect'}" + ("" if recal is None else
                                                        f" -> {after['chi2_per_dof']:.3g} after recalibration"))
    return Diagnosis(effect, effects_named, namer.rounds, before, with_effects, after, findings, loc, recal, channels,
                     meas.values, sigma, meas.conditions.as_dict(), y0, namer.base_values, y_after,
                     family.rotor_radius, time.perf_counter() - t0, namer.notes, "; ".join(namer.failures))


def _fit_settings(calibration: CalibrationSettings | None, diagnosis: DiagnosisSettings | None,
                  family) -> tuple[CalibrationSettings, DiagnosisSettings]:
    """The validated settings of the diagnosis's fits and of its naming step (``family.names``:
    the valid candidates)."""
    # the diagnosis's fits (localization, candidates, recalibration) use the truncated estimator:
    # its statistics (Λ, ΔBIC, pattern agreement, the gates) were set and validated with it, in and
    # out of family; the MAP estimator is not yet measured there
    cal = dataclasses.replace(calibration or CalibrationSettings(), estimator="truncated").validate()
    dset = (diagnosis or DiagnosisSettings()).validate(valid=family.names)
    return cal, dset


def _localize(family, measurements: Measurements, cal: CalibrationSettings, wrap: Callable, on_iteration,
              say: Callable[[str], None]) -> tuple:
    """Step 2: the correction field calibrated alone (a CalibrationResult), and ``measurements``
    with the σ it used or estimated [channel units]."""
    field_model = wrap(family.field_model(), "localization")
    say(f"localize: correction field, {len(field_model.parameters)} parameters")
    loc = Calibrator(field_model, measurements, cal, _tagged(on_iteration, "localization"), name="localization").run()
    meas = dataclasses.replace(measurements, sigma=loc.sigma)
    say(f"localize: {loc.n_retained} of {loc.n_params} θ retained, χ²/dof {loc.chi2_per_dof_after:.3g}")
    return loc, meas


def _find_disagreement(family, meas: Measurements, wrap: Callable, say: Callable[[str], None],
                       noise: str = "the stated σ") -> tuple:
    """Step 1: the nominal model's outputs y0, shape (n_points, n_channels) [channel units], its
    gap to the measurements (:func:`gap`) and where it disagrees (:func:`find`); ``noise`` says
    which σ the χ² is against (the localization's, stated or estimated with the correction field)."""
    channels = list(meas.channels)
    base_model = wrap(family.nominal_model(), "nominal")
    y0 = base_model.evaluate(np.zeros(0), meas.conditions).values
    before = gap(meas.values, y0, meas.sigma, channels)
    findings = find(meas.values, y0, meas.sigma, meas.conditions.as_dict(), channels, family.rotor_radius)
    say(f"find: nominal χ²/dof {before['chi2_per_dof']:.3g} ({p_is(before['p_value'])}) against {noise}")
    return y0, before, findings


def _name_effects(family, meas: Measurements, y0: np.ndarray, before: dict, field_after: np.ndarray,
                  cal: CalibrationSettings, dset: DiagnosisSettings, executor, wrap: Callable, fit_progress,
                  say: Callable[[str], None]) -> "_Namer":
    """Step 3: the naming rounds, against the noise plus the model-form tolerance.

    Parameters
    ----------
    y0, field_after : ndarray, shape (n_points, n_channels)
        The nominal model's outputs and the localized correction's [channel units].
    before : dict
        The nominal model's :func:`gap` against the noise alone.

    Returns
    -------
    _Namer
        With the rounds, the effects named and the model with them.
    """
    channels = list(meas.channels)
    candidates = tuple(dset.candidates) if dset.candidates is not None else tuple(family.names)
    if executor is None:
        from calib.executors import SerialExecutor
        executor = SerialExecutor()
    known = dataclasses.replace(cal, noise="known", sigma=None, retain="all")
    tol = dset.tolerance_of(channels)
    meas_name = dataclasses.replace(meas, sigma=np.hypot(meas.sigma, tol * np.abs(np.nan_to_num(y0))))
    before_name = gap(meas.values, y0, meas_name.sigma, channels)
    namer = _Namer(family, meas_name, y0, before_name["chi2"], (field_after - y0) / meas_name.sigma, dset,
                   known, executor, wrap, fit_progress, say, tol)
    # the global test gates everything, where the noise is stated: an estimated σ is fitted to the
    # localization's residuals, so the nominal model would pass against it by construction
    if cal.noise not in ESTIMATED_NOISE and before_name["p_value"] >= dset.significance:
        namer.consistent(before_name, within_tolerance=before["p_value"] < dset.significance)
    else:
        namer.run(candidates)
    return namer


def _recalibrate(family, namer: "_Namer", meas, cal, dset, wrap, on_iteration, say, effects_named):
    """The correction field recalibrated on top of the named effects (a CalibrationResult), or
    None when switched off or when it fails (the failure is noted)."""
    if not dset.recalibrate:
        return None
    model = wrap(family.field_model(namer.base_effects), "recalibration")
    known_field = dataclasses.replace(cal, noise="known", sigma=None)
    say("recalibrate: correction field on top of " + (", ".join(effects_named) or "the nominal model"))
    try:
        recal = Calibrator(model, meas, known_field, _tagged(on_iteration, "recalibration"),
                           name="recalibration").run()
    except CalibError as exc:
        namer.fail(f"the recalibration failed: {exc}; the figures after it are those with the named effect(s)")
        return None
    chi2 = gap(meas.values, recal.model_after, meas.sigma, list(meas.channels))["chi2"]
    start = gap(meas.values, namer.base_values, meas.sigma, list(meas.channels))["chi2"]
    if not chi2 <= start * (1 + RECALIBRATION_SLACK):
        # the nominal field is inside the search space: a larger χ² is an optimizer that ended
        # worse than where it started, never a better model
        namer.notes.append(f"the recalibration ended with χ² {chi2:.6g} above the {start:.6g} of the model "
                           f"with {', '.join(effects_named) or 'no effect'} ({recal.status}); it is not kept")
        say(f"recalibrate: {namer.notes[-1]}")
        return None
    return recal


def _tagged(callback, run: str):
    """``callback`` receiving Calibrator records with ``run`` added (None stays None)."""
    return None if callback is None else (lambda rec: callback({"run": run, **rec}))


def _fit_task(task: dict) -> dict:
    """Fit one candidate (module-level so executors can ship it to other processes).

    A candidate's own parameter (``task["own"]``: its indices) that ends where it started, to
    :data:`STUCK_TOLERANCE` of its scale, may sit on a stationary point of χ² (every derivative
    of a zero-magnitude effect's shape parameters vanishes at nominal): the fit is started
    again from :func:`away_start` and the one with the lower χ² is kept; the fit's status says
    which ("second start kept" / "second start not kept").
    """
    model = task["model"]
    meas = task["measurements"]
    st = dataclasses.replace(task["settings"], prior_check=False, tightening=False)   # a comparison: no advice
    names = [c.name for c in model.channels]
    cols = [names.index(c) for c in meas.channels]

    def fit(start=None):
        res = Calibrator(model, meas, st, name=task["name"], start=start).run()
        values = model.evaluate(res.p_hat, meas.conditions).values[:, cols]
        ok = np.isfinite(values).all(axis=1)
        chi2 = float(np.sum(((meas.values - values) / meas.sigma)[ok] ** 2)) if ok.any() else float("inf")
        return res, values, chi2

    try:
        res, values, chi2 = fit()
    except CalibError as exc:        # this candidate failed; the others are still compared
        return {"error": f"{type(exc).__name__}: {exc}"}
    own = list(task.get("own", range(res.n_params)))
    stuck = [j for j in own if abs(res.p_hat[j] - res.p_nominal[j]) <= STUCK_TOLERANCE * res.scale[j]]
    note = ""
    if stuck:
        try:
            res2, values2, chi2_2 = fit(away_start(res.p_hat, res.lower, res.upper, res.scale, stuck))
        except CalibError as exc:
            note = f"second start failed ({type(exc).__name__})"
        else:
            keep = chi2_2 < chi2
            note = f"second start {'kept' if keep else 'not kept'} (χ² {chi2_2:.6g} against {chi2:.6g})"
            if keep:
                res, values = res2, values2
    return {"result": res, "values": values, "start_note": note}


class _Namer:
    """Step 3 of :func:`diagnose`: naming rounds, each on top of the effects named before.

    A round that raises a :class:`~calib.errors.CalibError` (a fit that cannot run, an effect
    that cannot take its fitted values) is recorded with verdict ``failed`` and the failure in
    words; the naming stops there and what the earlier rounds found stands.
    """

    def __init__(self, family, meas, y0, chi2_nominal, field_change, dset, known, executor, wrap, fit_progress,
                 say, tolerance=None):
        self.family, self.meas, self.y0, self.field_change = family, meas, y0, field_change
        self.dset, self.known, self.executor, self.wrap = dset, known, executor, wrap
        self.fit_progress, self.say = fit_progress, say
        self.base_effects, self.named, self.rounds, self.notes, self.failures = [], [], [], [], []
        self.base_chi2, self.base_values = chi2_nominal, y0
        self.n_res = int(np.isfinite(y0).all(axis=1).sum() * y0.shape[1])
        self.remaining, self._fits = [], []       # _fits: the current round's fits (kept if it fails)
        self._effects = {}                        # the current round's candidate effects by label
        self.tolerance = np.zeros(y0.shape[1]) if tolerance is None else np.asarray(tolerance, float)

    def run(self, candidates) -> None:
        self.remaining = list(candidates)
        for round_no in range(self.dset.max_effects):
            if not self.remaining:
                break
            self._fits = []
            try:
                if self._round(round_no):
                    break
            except CalibError as exc:
                self.rounds.append({"base": self.family.names_of(self.base_effects), "candidates": self._fits,
                                    "verdict": "failed", "reason": f"failed: {exc}"})
                before = {0: "no effect was named", 1: "what round 1 found stands"}.get(
                    round_no, f"what rounds 1-{round_no} found stands")
                self.fail(f"naming round {round_no + 1} failed: {exc}; {before}")
                break

    def consistent(self, before: dict, within_tolerance: bool = False) -> None:
        """The nominal model passes the global χ² test (noise plus model-form tolerance): nothing
        is named (a likelihood ratio that is significant on top of a model that already fits is
        code-to-code residue, not an effect the data demand)."""
        what = ("within the model-form tolerance (it misses the noise alone, but not the noise plus the "
                "tolerance)" if within_tolerance else "consistent with the noise")
        reason = (f"the nominal model is {what} (χ²/dof {before['chi2_per_dof']:.3g} over {before['dof']} "
                  f"residuals, {p_is(before['p_value'])} ≥ significance {self.dset.significance:g}): no effect is "
                  "looked for")
        self.rounds.append({"base": [], "candidates": [], "verdict": "none", "reason": reason})
        self.say(f"name: {reason}")

    def fail(self, message: str) -> None:
        self.failures.append(message)
        self.notes.append(message)
        self.say(message)

    def verdict(self) -> tuple[str, list]:
        """The diagnosis' one-word result and the effects named (in order)."""
        effects_named = [n for n in self.named if not n.startswith("ambiguous:")]
        if self.named and self.named[0].startswith("ambiguous:"):
            return "ambiguous", effects_named
        return (effects_named[0] if effects_named else "none"), effects_named

    def _round(self, round_no: int) -> bool:
        """One naming round; True when the naming is over."""
        labels, effects = self._applicable()
        if not labels:
            return True
        self._effects = effects
        self._fits = fits = self._fit(round_no, labels, effects)
        rnd, best = self._judge(fits)
        if best is None:
            self.rounds.append(rnd)
            if rnd["verdict"] == "ambiguous" and not self.named:
                self.named.append("ambiguous:" + "+".join(rnd["ambiguous"]))
            return True
        new_base = self.family.add(self.base_effects, best)    # may raise: the round then fails
        self.rounds.append(rnd)
        self.named.append(best.effect)
        self.base_effects = new_base
        self.base_chi2, self.base_values = best.chi2, best.model_values
        self.remaining = [c for c in self.remaining if c != best.effect]
        # a further effect is looked for only while the model is still inconsistent with the noise
        fit_now = gap(self.meas.values, self.base_values, self.meas.sigma, list(self.meas.channels),
                      self.family.n_parameters(self.base_effects))
        if fit_now["p_value"] >= self.dset.significance:
            self.say(f"name: with {', '.join(self.named)} the model is consistent with the noise (χ²/dof "
                     f"{fit_now['chi2_per_dof']:.3g}, {p_is(fit_now['p_value'])}); no further effect is looked for")
            return True
        return False

    def _applicable(self) -> tuple[list, dict]:
        """Labels and effects of the remaining candidates' variants that can act on this rotor."""
        labels, effects = [], {}
        for c in list(self.remaining):
            try:
                variants = self.family.variants(c, self.dset.candidate_options.get(c, {}))
                for label, effect in variants:
                    # an effect that cannot act on this rotor (e.g. no reference Reynolds number) is
                    # reported as not applicable, not fitted
                    self.family.check(self.base_effects, effect, self.meas.conditions)
            except InputError as exc:
                self.notes.append(f"candidate {c} not applicable: {exc}")
                self.say(f"name: candidate {c} not applicable: {exc}")
                self.remaining.remove(c)
                continue
            for label, effect in variants:
                labels.append(label)
                effects[label] = effect
        return labels, effects

    def _fit(self, round_no: int, labels: list, effects: dict) -> list:
        """Every candidate fitted on top of the base effects, scored against the base model."""
        n_base = self.family.n_parameters(self.base_effects)
        tasks = [{"name": lab, "measurements": self.meas, "settings": self.known,
                  "own": list(range(n_base, n_base + len(effects[lab].parameters()))),
                  "model": self.wrap(self.family.candidate_model(self.base_effects, effects[lab]),
                                     f"round {round_no + 1}: {lab}")} for lab in labels]
        self.say(f"name (round {round_no + 1}): fitting {len(tasks)} candidates")
        outs = self.executor.map(_fit_task, tasks, self.fit_progress)
        alpha = self.dset.significance / max(len(self.remaining), 1)
        failed = [(lab, out["error"]) for lab, out in zip(labels, outs) if "error" in out]
        for lab, message in failed:
            self.notes.append(f"round {round_no + 1}: the fit of candidate {lab} failed and it is left out of the "
                              f"comparison: {message}")
            self.say(f"name: {self.notes[-1]}")
        if len(failed) == len(labels):
            raise CalibError(f"every candidate fit of round {round_no + 1} failed (first: {failed[0][1]})")
        return [self._score(lab, out, effects[lab], alpha) for lab, out in zip(labels, outs) if "error" not in out]

    def _score(self, label: str, out: dict, effect, alpha: float) -> CandidateFit:
        res, values = out["result"], out["values"]
        meas, sigma = self.meas, self.meas.sigma
        own = list(range(self.family.n_parameters(self.base_effects), res.n_params))
        chi2 = float(np.sum(((meas.values - values) / sigma)[np.isfinite(values).all(axis=1)] ** 2))
        k = len(own)
        lr, p = likelihood_ratio(self.base_chi2, chi2, k)
        agree = pattern_agreement((values - self.base_values) / sigma,
                                  self.field_change - (self.base_values - self.y0) / sigma)
        params = _parameter_records(res, own)
        size, words, exceeds = effect_size(values, self.base_values, self.tolerance, list(meas.channels),
                                           meas.conditions.wind_speed)
        return CandidateFit(label, params, chi2, k, -0.5 * chi2, chi2 + k * np.log(self.n_res), lr, p,
                            p < alpha and exceeds, pattern_agreement=agree, status=res.status,
                            start=out.get("start_note", ""), p_hat=np.array(res.p_hat, float),
                            spec=self.family.spec(effect), model_values=values, effect=label.split(":")[0],
                            at_bound=[q["name"] for q in params if q["at_bound"]], effect_size=size,
                            effect_text=words)

    def _judge(self, fits: list) -> tuple[dict, CandidateFit | None]:
        """The round's record (BIC weights set, candidates sorted by BIC) and the candidate it
        names (None for ``none`` and ``ambiguous``): :func:`calib.diagnosis.verdict.judge_round`."""
        rnd, best = judge_round(fits, self.base_chi2, self.family.names_of(self.base_effects), self.dset,
                                lambda a, b: _separation_of(self, a, b))
        self.say(f"name: {rnd['reason']}")
        return rnd, best
