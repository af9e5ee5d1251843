"""Step 3 of the diagnosis (:func:`calib.diagnosis.core.diagnose`): the naming rounds.

Each round fits every remaining candidate effect on top of the effects named before
(:func:`fit_task`, one per candidate, through the executor), scores it against the model
without it (likelihood ratio, BIC, pattern agreement, effect size) and asks
:func:`calib.diagnosis.verdict.judge_round` for the verdict; an ``ambiguous`` verdict comes
with the measurement that would tell the two rivals apart (:func:`separation_of`).
:class:`Namer` holds the rounds' state.

A model-form candidate (the BEM's own induction model: ``Effect.kind = "model_form"``) is named as
model form, not as a physical effect. Model form comes first, in every round: a physical effect
must earn its place (:data:`LATER_EFFECT_SHARE`) after an earlier effect and over the round's
significant model-form candidates, all of them fitted together (also in a round ambiguous between a
physical effect and a model-form candidate), and one not separable from the model form
(:mod:`calib.diagnosis.model_form`) is not named.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from calib.calibration.calibrator import Calibrator
from calib.diagnosis.candidate_parameters import STUCK_TOLERANCE, away_start, parameter_records
from calib.diagnosis.figures_of_merit import effect_size, gap
from calib.diagnosis.model_form import model_form_r2, not_separable
from calib.diagnosis.over_model_form import over_model_form
from calib.diagnosis.ranking import likelihood_ratio, pattern_agreement
from calib.diagnosis.result import CandidateFit
from calib.diagnosis.share import share_record, share_test
from calib.diagnosis.separation import envelope_words, probe_conditions, probe_limits, separating_probes
from calib.diagnosis.verdict import judge_round
from calib.errors import CalibError, InputError
from calib.types import CONDITION_FIELDS, OperatingConditions
from calib.words import p_is

#: Share of the misfit left beyond the noise and the model-form tolerance (χ² − dof of the model
#: with the effects named so far, against σ² + (tolerance·y)²) that a physical effect's likelihood
#: ratio Λ must explain to be named after another effect, or over a significant model-form
#: candidate (fitted on top of it) [-]. Set by a rule stated before the measurement (CHANGELOG.md,
#: issue 37; ``benchmarks/share_threshold.py``, :func:`calib.diagnosis.share.balanced_threshold`): the
#: threshold where the mean chance of missing a true hidden effect equals the mean chance of naming a
#: stand-in, each decision's chance from its own noise (the share test's z at the threshold; a later
#: effect must also pass its z_needed). Measured 2026-11-28 on the lifting-line battery, both wakes,
#: every data set, development seeds 26000-26019 (369 decisions, ``tests/data/share_threshold/
#: development.json``) plus the three CCBlade stand-ins of seeds 25000-25019 (49-54 %): true effects
#: (121 point decisions over the model form) 60-96 %, the lowest fast-wake erosion (60-65 %, ± 4-5 %);
#: stand-ins by the point share (102) 1-56 %, by the share test (146 later effects) 4-117 %, the high
#: ones shares of small misfits (± 10-20 %); balance at 0.620 (miss 2.6 %, false naming 2.7 %), 0.62
#: also on seeds 26000-26009 alone. A later effect must exceed it beyond the share's noise
#: (:func:`calib.diagnosis.share.share_test`); over the joint model form, the point share decides.
LATER_EFFECT_SHARE = 0.62


def fit_task(task: dict) -> dict:
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
        values = model.evaluate(res.estimate.p_hat, meas.conditions).values[:, cols]
        ok = np.isfinite(values).all(axis=1)
        chi2 = float(np.sum(((meas.values - values) / meas.sigma)[ok] ** 2)) if ok.any() else float("inf")
        return res, values, chi2

    try:
        res, values, chi2 = fit()
    except CalibError as exc:        # this candidate failed; the others are still compared
        return {"error": f"{type(exc).__name__}: {exc}"}
    own = list(task.get("own", range(res.n_params)))
    est = res.estimate
    stuck = [j for j in own if abs(est.p_hat[j] - est.p_nominal[j]) <= STUCK_TOLERANCE * est.scale[j]]
    note = ""
    if stuck:
        try:
            res2, values2, chi2_2 = fit(away_start(res.estimate.p_hat, res.estimate.lower, res.estimate.upper,
                                                   res.estimate.scale, stuck))
        except CalibError as exc:
            note = f"second start failed ({type(exc).__name__})"
        else:
            keep = chi2_2 < chi2
            note = f"second start {'kept' if keep else 'not kept'} (χ² {chi2_2:.6g} against {chi2:.6g})"
            if keep:
                res, values = res2, values2
    return {"result": res, "values": values, "start_note": note}


class Namer:
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
        self._named_fits = []                     # the CandidateFit of each named effect
        self._collinearity = {}                   # the round's R² of each candidate with the named model form
        self._over_form = None                    # the round's physical effect that earned its place over model form
        self.tolerance = np.zeros(y0.shape[1]) if tolerance is None else np.asarray(tolerance, float)

    def run(self, candidates) -> None:
        """The naming rounds over ``candidates``: up to ``max_effects`` physical effects, and the
        model-form parameters among them besides (they do not count against it)."""
        self.remaining = list(candidates)
        n_form = sum(self.family.kind(c) == "model_form" for c in candidates)
        for round_no in range(self.dset.max_effects + n_form):
            if not self.remaining or len(self.named) - len(self.model_form) >= self.dset.max_effects:
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

    @property
    def model_form(self) -> list:
        """The model-form parameters named (the induction model's, not physical effects), in order."""
        return [f.effect for f in self._named_fits if f.kind == "model_form"]

    def verdict(self) -> tuple[str, list]:
        """The diagnosis' one-word result (the first physical effect named, ``ambiguous`` or
        ``none``) and every effect named, model form included (in order)."""
        effects_named = [n for n in self.named if not n.startswith("ambiguous:")]
        if self.named and self.named[0].startswith("ambiguous:"):
            return "ambiguous", effects_named
        physical = [n for n in effects_named if n not in self.model_form]
        return (physical[0] if physical else "none"), effects_named

    def _round(self, round_no: int) -> bool:
        """One naming round; True when the naming is over."""
        labels, effects = self._applicable()
        if not labels:
            return True
        self._effects, self._over_form = effects, None
        self._fits = fits = self._fit(round_no, labels, effects)
        rnd, best = self._judge(fits)
        if best is None and rnd["verdict"] == "ambiguous":
            best = self._ambiguous_with_model_form(round_no, rnd, fits)
        elif best is not None and best.kind != "model_form":
            # model form first, in every round: a physical effect is named over a significant
            # model-form candidate only when it also explains most of what that candidate leaves
            forms = [f for f in fits if f.kind == "model_form" and f.significant]
            if forms:
                best = self._over_model_form(round_no, rnd, best, forms, fits)
        if best is not None and best.kind != "model_form" and self._named_fits and best is not self._over_form:
            # (a physical effect that earned its place on top of the named effects and the round's model
            # form has passed the stricter test already)
            best = self._earns_place(rnd, best)
        if best is not None and best.kind != "model_form" and self.model_form:
            best = self._separable(rnd, best)
        if best is not None and best.kind == "model_form":
            rnd["reason"] = ("model form (the BEM's own induction model, not a missing physical effect): "
                             + rnd["reason"])
        if best is None:
            self.rounds.append(rnd)
            if rnd["verdict"] == "ambiguous" and not self.named:
                self.named.append("ambiguous:" + "+".join(rnd["ambiguous"]))
            return True
        new_base = self.family.add(self.base_effects, best)    # may raise: the round then fails
        self.rounds.append(rnd)
        self.named.append(best.effect)
        self._named_fits.append(best)
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

    def _separable(self, rnd: dict, best: CandidateFit) -> CandidateFit | None:
        """``best``, or None with ``rnd`` turned ``none`` when it is not separable from the model
        form named so far (:func:`calib.diagnosis.model_form.not_separable`)."""
        reason = not_separable(self._collinearity.get(best.name), best, self.model_form)
        return best if reason is None else rnd.update(verdict="none", reason=reason)   # dict.update: None

    def _ambiguous_with_model_form(self, round_no: int, rnd: dict, fits: list) -> CandidateFit | None:
        """An ``ambiguous`` round while a model-form candidate is significant, model form first: the
        best model-form candidate when the pair's physical effect (the better one, for a pair of physical
        effects) does not earn its place on top of the joint model form (:meth:`_over_model_form`); a third
        physical effect when it is the one that earns its place there (as an unambiguous round names it over one
        that fits better alone: lifting line, fast wake, seed 26012); else None (the round stays ambiguous). A
        tied pair may both stand in for the induction model's form (same data, erosion hidden, seed 26011).
        """
        pair = [next((f for f in fits if f.effect == name and f.significant), None) for name in rnd["ambiguous"]]
        forms = [f for f in fits if f.kind == "model_form" and f.significant]
        if any(f is None for f in pair) or not forms or all(f.kind == "model_form" for f in pair):
            return None
        physical = min((f for f in pair if f.kind == "physical"), key=lambda f: f.bic)
        form = next((f for f in pair if f.kind == "model_form"), None)
        before = dict(rnd)
        chosen = self._over_model_form(round_no, rnd, physical, forms, fits)
        third = chosen.kind == "physical" and form is None and chosen.effect not in before["ambiguous"]
        if third or (chosen.kind == "model_form" and (form is None or chosen is form)):
            rnd.pop("ambiguous", None), rnd.pop("separate", None)
            rnd["reason"] += (f" (the round was ambiguous between {' and '.join(before['ambiguous'])} alone; on top "
                              f"of the model form {chosen.effect} fits best of the candidates separable from it)"
                              if third else f" (the round was ambiguous: {before['reason']})")
            return chosen
        rnd.clear()
        rnd.update(before)
        self._over_form = None
        return None

    def _over_model_form(self, round_no: int, rnd: dict, best: CandidateFit, forms: list,
                         fits: list) -> CandidateFit:
        """:func:`calib.diagnosis.over_model_form.over_model_form` (the physical candidate that earns its
        place over the joint model form ``forms``, else the best of ``forms``)."""
        return over_model_form(self, round_no, rnd, best, forms, fits, LATER_EFFECT_SHARE, fit_task)

    def _earns_place(self, rnd: dict, best: CandidateFit) -> CandidateFit | None:
        """``best`` when a later effect earns its place, else None with ``rnd`` turned ``none``.

        It must explain (Λ) at least :data:`LATER_EFFECT_SHARE` of the misfit the model with the
        effects named so far leaves beyond the noise and the model-form tolerance; a named effect
        that sits at a bound of its parameters is said to may not fit in form, so that the later
        one may stand in for the mismatch.
        """
        dof = self.n_res - self.family.n_parameters(self.base_effects)
        excess = self.base_chi2 - dof
        n_physical = len({f.effect for f in self._fits if f.kind != "model_form"})
        test = share_test(best.lr_statistic, best.n_params, self.base_chi2, dof, LATER_EFFECT_SHARE,
                          self.dset.significance, n_physical)
        rnd.setdefault("shares", []).append(share_record(best.name, best.effect, best.lr_statistic, best.n_params,
                                                         self.base_chi2, dof, n_physical, "test", test))
        pinned = [f for f in self._named_fits if f.at_bound]
        form = "".join(f"; {f.effect} sits at a bound ({f.bound_phrase()}): its form may not fit the data, and "
                       f"{best.effect} may stand in for that mismatch" for f in pinned)
        if test.passed:
            rnd["reason"] += (f"; of the misfit left with {', '.join(self.named)} beyond the noise and the model-form "
                              f"tolerance it explains {test.words(LATER_EFFECT_SHARE)}{form}")
            return best
        named = ", ".join(self.named)
        rnd.update(verdict="none", reason=(
            f"{best.name} would explain only {test.words(LATER_EFFECT_SHARE)} of the misfit left with {named} "
            f"beyond the noise and the model-form tolerance (Λ = {best.lr_statistic:.4g} of χ² − dof = {excess:.4g}; "
            f"a further effect is named when it explains at least {100 * LATER_EFFECT_SHARE:.0f} % beyond the noise, "
            f"one-sided test at {self.dset.significance:g} over the round's {max(n_physical, 1)} physical "
            f"candidates): not named, as the misfit left is more likely the form of {named} than another effect "
            f"({best.effect_text}){form}"))
        return None

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
        outs = self.executor.map(fit_task, tasks, self.fit_progress)
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
        params = parameter_records(res, own)
        corr = getattr(getattr(res, "identifiability", None), "correlation", None)
        self._collinearity[label] = model_form_r2(corr, [(e.parameters(), self.family.kind(e.name))
                                                         for e in self.base_effects], own)
        size, words, exceeds = effect_size(values, self.base_values, self.tolerance, list(meas.channels),
                                           meas.conditions.wind_speed)
        return CandidateFit(label, params, chi2, k, -0.5 * chi2, chi2 + k * np.log(self.n_res), lr, p,
                            p < alpha and exceeds, pattern_agreement=agree, status=res.estimate.status,
                            start=out.get("start_note", ""), p_hat=np.array(res.estimate.p_hat, float),
                            spec=self.family.spec(effect), model_values=values, effect=label.split(":")[0],
                            at_bound=[q["name"] for q in params if q["at_bound"]], effect_size=size,
                            effect_text=words, kind=self.family.kind(label.split(":")[0]))

    def _judge(self, fits: list) -> tuple[dict, CandidateFit | None]:
        """The round's record (BIC weights set, candidates sorted by BIC) and the candidate it
        names (None for ``none`` and ``ambiguous``): :func:`calib.diagnosis.verdict.judge_round`."""
        rnd, best = judge_round(fits, self.base_chi2, self.family.names_of(self.base_effects), self.dset,
                                lambda a, b: separation_of(self, a, b))
        self.say(f"name: {rnd['reason']}")
        return rnd, best


def separation_of(namer: Namer, a: CandidateFit, b: CandidateFit) -> dict:
    """The measurement that would tell ``a`` from ``b`` (:mod:`calib.diagnosis.separation`): {"text", "probes",
    "envelope", "fingerprints"}; a probe that cannot be evaluated is said, never raised."""
    fam, meas = namer.family, namer.meas
    names = (a.effect, b.effect)
    fingerprints = {n: fam.fingerprint(n) for n in names if fam.fingerprint(n)}
    envelope = envelope_words(meas.conditions, fam.rotor_radius)
    out = {"probes": [], "envelope": envelope, "fingerprints": fingerprints}
    try:
        probes = probe_conditions(meas.conditions, fam.rotor_radius, fam.schedule)
        both = OperatingConditions(*(np.concatenate([getattr(meas.conditions, f), getattr(probes, f)])
                                     for f in CONDITION_FIELDS))
        channels = fam.probe_channels(list(meas.channels))
        va, units = fam.predict(namer.base_effects, namer._effects[a.name], a.p_hat, both, channels)
        vb, _ = fam.predict(namer.base_effects, namer._effects[b.name], b.p_hat, both, channels)
    except CalibError as exc:
        out["text"] = f"the probes that would separate them could not be evaluated ({exc})"
        return out
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = {c: float(np.nanmedian(np.where(namer.y0[:, j] != 0, meas.sigma[:, j] / np.abs(namer.y0[:, j]), np.nan)))
               for j, c in enumerate(meas.channels)}
    rel = {c: r for c, r in rel.items() if np.isfinite(r) and r > 0}
    found = separating_probes(va, vb, both, channels, list(meas.channels), rel, len(meas.conditions),
                              fam.rotor_radius)
    unit = dict(zip(channels, units))
    out["probes"] = [{**dataclasses.asdict(p), "words": p.words(names, unit[p.channel])} for p in found]
    if not found:
        text = "no probe could compare them"
    elif found[0].separation > 1.0:
        text = "to tell them apart, measure " + "; or ".join(p["words"] for p in out["probes"] if p["separation"] > 1)
    else:
        text = ("no probe considered separates them beyond the noise and model-form tolerance (closest: "
                f"{out['probes'][0]['words']})")
    text += f"; probes {probe_limits(meas.conditions, fam.schedule)[2]}; the campaign measured {envelope}"
    if fingerprints:
        text += "; fingerprints: " + "; ".join(f"{n}: {fp}" for n, fp in fingerprints.items())
    out["text"] = text
    return out
