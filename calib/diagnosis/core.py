"""The diagnosis: find where model and measurements disagree, name the missing
effect, add it, show the gap shrink (docs/theory.md, Diagnosis).

This module runs the steps (:func:`diagnose`); the naming rounds of step 3 are in
:mod:`calib.diagnosis.naming`. Beside them live the settings (:mod:`calib.diagnosis.settings`),
the result (:mod:`calib.diagnosis.result`), the figures of merit (:mod:`calib.diagnosis.figures_of_merit`), the candidates of the native BEM
(:mod:`calib.diagnosis.bem_family`) and their fitted parameters
(:mod:`calib.diagnosis.candidate_parameters`), the statistics that rank candidates
(:mod:`calib.diagnosis.ranking`) and the verdict of a naming round (:mod:`calib.diagnosis.verdict`).

Steps
-----
1. **Find**: the nominal model's whitened residuals r = (z − y)/σ; the χ² test (χ²/N and its
   p-value) says whether the model is consistent with the noise; per channel and against
   tip-speed ratio, pitch and wind speed the residuals say where it is not.
2. **Localize**: the SVD calibration of the correction field (:class:`calib.calibration.calibrator.Calibrator`,
   automatic truncation) says which (α, η) region of the polars would have to change; with
   ``noise = "ml"`` it also gives the noise σ the later steps use, and runs before step 1. With a
   stated noise step 1 and its χ² gate come first: a nominal model that passes the gate is not
   localized (no candidate is fitted, so nothing uses the localized correction), unless the
   recalibration is asked for, which on the nominal model with the stated σ is the localization's
   fit (the same field model, σ and settings): it is run once and serves as both
   (``Diagnosis.localization`` is None when it did not run).
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
from calib.calibration.calibrator import CalibrationSettings, Calibrator
from calib.calibration.errors_in_variables import uncertain_conditions
from calib.calibration.noise import initial_sigma
from calib.corrections import CorrectionGrid
from calib.diagnosis.bem_family import BemFamily, facility_effects
from calib.diagnosis.figures_of_merit import find, gap
from calib.diagnosis.naming import Namer
from calib.diagnosis.result import Diagnosis
from calib.diagnosis.settings import DiagnosisSettings
from calib.errors import CalibError, InputError
from calib.measurements import Measurements
from calib.words import p_is

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
        :func:`calib.models.recorded_model.recorded`, which records each call and answers it on resume).
    fit_progress : callable(done, total), optional
        Called as the candidate fits of a round finish.
    family : optional
        The models to calibrate (default :class:`BemFamily` of ``rotor``, ``grid``,
        ``settings``); e.g. :class:`calib.diagnosis.fmu.FmuFamily` for an FMU.
    on_iteration : callable(dict), optional
        Receives every optimizer iteration record of the localization and the recalibration
        (:class:`~calib.calibration.calibrator.Calibrator` records with ``run`` added).

    Returns
    -------
    Diagnosis
        With ``failure`` non-empty when a naming round or the recalibration failed: the
        rounds before it, and the gap with the effects they named, are still reported.
    """
    t0 = time.perf_counter()
    settings = settings or BemSettings()
    channels = list(measurements.channels)
    if family is None:
        fixed = facility_effects((diagnosis or DiagnosisSettings()).validate(), rotor)
        family = BemFamily(rotor, channels, grid, settings, rotor_source, fixed=fixed)
    cal, dset = _fit_settings(calibration, diagnosis, family)
    _refuse_condition_sigma(measurements, cal)
    say = progress or (lambda s: None)
    wrap = wrap or (lambda model, label: model)

    if cal.noise in ESTIMATED_NOISE:
        # 2. localize first: it estimates the σ every later step uses
        loc, meas = _localize(family, measurements, cal, wrap, on_iteration, say, dset.recalibrate)
        # 1. find
        y0, before, findings = _find_disagreement(family, meas, wrap, say, loc.noise_words())
        consistent = None
    else:
        # 1. find first: the σ is stated, and a nominal model that passes the χ² gate needs no
        # localization (its field fit is run only when the recalibration needs it, and then once)
        meas = dataclasses.replace(measurements, sigma=initial_sigma(measurements, cal))
        y0, before, findings = _find_disagreement(family, meas, wrap, say, _stated_noise_words(cal, meas, family))
        consistent = _consistent(meas, y0, before, dset)
        loc = None
        if consistent is None or dset.recalibrate:
            loc, _ = _localize(family, measurements, cal, wrap, on_iteration, say, dset.recalibrate)
        else:
            say("localize: not run: the nominal model passes the χ² test against the stated noise, so there is "
                "nothing to localize")
    sigma = meas.sigma

    # 3. name, up to max_effects rounds (a round that fails ends the naming; earlier rounds stand),
    # against the noise plus the model-form tolerance
    namer = _name_effects(family, meas, y0, before, None if loc is None else loc.fit.model_after, cal, dset,
                          executor, wrap, fit_progress, say, consistent)
    effect, effects_named = namer.verdict()
    n_fit = family.n_parameters(namer.base_effects)
    with_effects = gap(meas.values, namer.base_values, sigma, channels, n_fit)

    # 4. add + recalibrate the field on top (with the stated σ and nothing named, the localization
    # is that fit: it is reused, not run again)
    same_fit = loc if (cal.noise not in ESTIMATED_NOISE and not namer.base_effects) else None
    recal = _recalibrate(family, namer, meas, cal, dset, wrap, on_iteration, say, effects_named, same_fit)
    y_after = None if recal is None else recal.fit.model_after
    after = with_effects if recal is None else gap(meas.values, y_after, sigma, channels, n_fit + recal.n_retained)
    say(f"show: χ²/dof {before['chi2_per_dof']:.3g} -> {with_effects['chi2_per_dof']:.3g} with "
        f"{', '.join(effects_named) or 'no effect'}" + ("" if recal is None else
                                                        f" -> {after['chi2_per_dof']:.3g} after recalibration"))
    return Diagnosis(effect, effects_named, namer.rounds, before, with_effects, after, findings, loc, recal, channels,
                     meas.values, sigma, meas.conditions.as_dict(), y0, namer.base_values, y_after,
                     family.rotor_radius, time.perf_counter() - t0, namer.notes, "; ".join(namer.failures),
                     model_form=namer.model_form, channel_units=_channel_units(family, channels))


def _channel_units(family, channels: list) -> list:
    """The units of ``channels`` as the nominal model states them ("" where it does not)."""
    units = {c.name: c.unit for c in family.nominal_model().channels}
    return [units.get(c, "") for c in channels]


def _stated_noise_words(cal: CalibrationSettings, meas: Measurements, family) -> str:
    """Which stated noise the χ² is against, in the words of
    :meth:`~calib.calibration.result.CalibrationResult.noise_words` (which says it for a fit)."""
    how = {"known": "the stated σ", "repeats": "the σ of the repeated records",
           "relative": "the stated σ relative to each point's value"}.get(cal.noise, cal.noise)
    if cal.noise == "relative":
        return f"{how} ({cal.noise})"
    units = _channel_units(family, list(meas.channels))
    return f"{how} ({cal.noise}): " + ", ".join(f"{c} {float(s):.3g} {u}" for c, u, s in
                                                   zip(meas.channels, units, meas.sigma[0]))


def _consistent(meas: Measurements, y0: np.ndarray, before: dict, dset: DiagnosisSettings) -> dict | None:
    """The global χ² gate of a stated noise: the nominal model's :func:`gap` against the noise plus
    the model-form tolerance (the naming's σ) when it passes at ``significance``, with
    ``within_tolerance`` (it misses the noise alone); None when it fails (effects are looked for)."""
    sigma = _naming_sigma(meas, y0, dset)
    before_name = gap(meas.values, y0, sigma, list(meas.channels))
    if before_name["p_value"] < dset.significance:
        return None
    return {"gap": before_name, "within_tolerance": before["p_value"] < dset.significance}


def _naming_sigma(meas: Measurements, y0: np.ndarray, dset: DiagnosisSettings) -> np.ndarray:
    """The naming's σ: the noise plus the model-form tolerance, shape (n_points, n_channels)
    [channel units]."""
    tol = dset.tolerance_of(list(meas.channels))
    return np.hypot(meas.sigma, tol * np.abs(np.nan_to_num(y0)))


def _refuse_condition_sigma(measurements: Measurements, cal: CalibrationSettings) -> None:
    """Refuse operating conditions with a stated σ: the diagnosis's fits do not carry them (its
    localization would hand the effective σ of one fit on as the next fits' output noise)."""
    if uncertain_conditions(measurements, cal) is not None:
        raise InputError("the diagnosis does not take the operating conditions' σ (errors in variables) "
                         "into its fits yet; diagnose with errors_in_variables = \"ignore\" (the conditions "
                         "as read), then calibrate with them", measurements.source, field="errors_in_variables")


def _fit_settings(calibration: CalibrationSettings | None, diagnosis: DiagnosisSettings | None,
                  family) -> tuple[CalibrationSettings, DiagnosisSettings]:
    """The validated settings of the diagnosis's fits and of its naming step (``family.names``:
    the valid candidates)."""
    # the diagnosis's fits (localization, candidates, recalibration) use the truncated estimator:
    # its statistics (Λ, ΔBIC, pattern agreement, the gates) were set and validated with it, in and
    # out of family; the MAP estimator is not yet measured there
    cal = dataclasses.replace(calibration or CalibrationSettings(), estimator="truncated").validate()
    dset = (diagnosis or DiagnosisSettings()).validate(valid=family.names)
    if dset.cross_section is not None and not hasattr(family, "fixed"):
        raise InputError("a stated cross-section applies Glauert's blockage to the native BEM; this model family "
                         "cannot take it (model the facility in the FMU, or leave cross_section out to estimate "
                         "blockage where the FMU maps it)", "DiagnosisSettings", field="diagnosis.cross_section")
    return cal, dset


def _localize(family, measurements: Measurements, cal: CalibrationSettings, wrap: Callable, on_iteration,
              say: Callable[[str], None], recalibrates: bool) -> tuple:
    """Step 2: the correction field calibrated alone (a CalibrationResult), and ``measurements``
    with the σ it used or estimated [channel units]. ``recalibrates``: the diagnosis recalibrates (with a
    stated σ the localization may then be that result, so it keeps the calibration's every term)."""
    field_model = wrap(family.field_model(), "localization")
    say(f"localize: correction field, {len(field_model.parameters)} parameters")
    if field_model.capabilities.derivatives != "exact" and not (recalibrates and cal.noise not in ESTIMATED_NOISE):
        # a model whose Jacobians cost simulations (an FMU), and a fit that serves the σ, the pattern agreement
        # and the report only, never as the recalibration's result: its prior check and frozen-curvature samples
        # are not used (on the bundled FMU's named-effect case they were ~900 of its 1 254 simulations)
        cal = dataclasses.replace(cal, prior_check=False, curvature_samples=0)
    loc = Calibrator(field_model, measurements, cal, _tagged(on_iteration, "localization"), name="localization").run()
    meas = dataclasses.replace(measurements, sigma=loc.fit.sigma)
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


def _name_effects(family, meas: Measurements, y0: np.ndarray, before: dict, field_after: np.ndarray | None,
                  cal: CalibrationSettings, dset: DiagnosisSettings, executor, wrap: Callable, fit_progress,
                  say: Callable[[str], None], consistent: dict | None = None) -> Namer:
    """Step 3: the naming rounds, against the noise plus the model-form tolerance.

    Parameters
    ----------
    y0, field_after : ndarray, shape (n_points, n_channels)
        The nominal model's outputs and the localized correction's [channel units]; ``field_after``
        None when nothing was localized (then ``consistent`` is given: no candidate is fitted).
    before : dict
        The nominal model's :func:`gap` against the noise alone.
    consistent : dict, optional
        :func:`_consistent`'s passed gate of a stated noise, decided before the localization.

    Returns
    -------
    Namer
        With the rounds, the effects named and the model with them.
    """
    channels = list(meas.channels)
    excluded = dset.excluded()
    candidates = tuple(c for c in (dset.candidates if dset.candidates is not None else family.names)
                       if c not in excluded)
    if executor is None:
        from calib.executors import SerialExecutor
        executor = SerialExecutor()
    known = dataclasses.replace(cal, noise="known", sigma=None, retain="all")
    tol = dset.tolerance_of(channels)
    meas_name = dataclasses.replace(meas, sigma=_naming_sigma(meas, y0, dset))
    before_name = gap(meas.values, y0, meas_name.sigma, channels)
    field_change = None if field_after is None else (field_after - y0) / meas_name.sigma
    namer = Namer(family, meas_name, y0, before_name["chi2"], field_change, dset,
                   known, executor, wrap, fit_progress, say, tol)
    for effect in getattr(family, "fixed", ()):
        namer.notes.append(f"every model includes Glauert's blockage at the known area ratio "
                           f"{effect.options['area_ratio']:.4g} (swept area over the stated cross-section)")
    for name, why in excluded.items():
        if name in family.names:
            namer.notes.append(f"{name} is not a candidate: {why}")
            say(f"name: {namer.notes[-1]}")
    # the global test gates everything, where the noise is stated (decided before, by _consistent):
    # an estimated σ is fitted to the localization's residuals, so the nominal model would pass
    # against it by construction
    if consistent is not None:
        namer.consistent(consistent["gap"], within_tolerance=consistent["within_tolerance"])
    else:
        namer.run(candidates)
    return namer


def _recalibrate(family, namer: Namer, meas, cal, dset, wrap, on_iteration, say, effects_named, same_fit=None):
    """The correction field recalibrated on top of the named effects (a CalibrationResult), or
    None when switched off or when it fails (the failure is noted).

    ``same_fit``: a result of this very fit (the localization, with a stated σ and nothing named:
    the same field model, σ and settings), taken instead of fitting again."""
    if not dset.recalibrate:
        return None
    say("recalibrate: correction field on top of " + (", ".join(effects_named) or "the nominal model")
        + (" (the localization's fit: the same model, σ and settings)" if same_fit is not None else ""))
    if same_fit is not None:
        recal = same_fit
    else:
        model = wrap(family.field_model(namer.base_effects), "recalibration")
        known_field = dataclasses.replace(cal, noise="known", sigma=None)
        try:
            recal = Calibrator(model, meas, known_field, _tagged(on_iteration, "recalibration"),
                               name="recalibration").run()
        except CalibError as exc:
            namer.fail(f"the recalibration failed: {exc}; the figures after it are those with the named effect(s)")
            return None
    chi2 = gap(meas.values, recal.fit.model_after, meas.sigma, list(meas.channels))["chi2"]
    start = gap(meas.values, namer.base_values, meas.sigma, list(meas.channels))["chi2"]
    if not chi2 <= start * (1 + RECALIBRATION_SLACK):
        # the nominal field is inside the search space: a larger χ² is an optimizer that ended
        # worse than where it started, never a better model
        namer.notes.append(f"the recalibration ended with χ² {chi2:.6g} above the {start:.6g} of the model "
                           f"with {', '.join(effects_named) or 'no effect'} ({recal.estimate.status}); it is not kept")
        say(f"recalibrate: {namer.notes[-1]}")
        return None
    return recal


def _tagged(callback, run: str):
    """``callback`` receiving Calibrator records with ``run`` added (None stays None)."""
    return None if callback is None else (lambda rec: callback({"run": run, **rec}))
