"""A physical effect against the whole model form in a naming round (issue 37, items 3-4):
:func:`over_model_form`, used by :class:`calib.diagnosis.naming.Namer`.

A physical candidate that fits better than a significant model-form candidate (the BEM's own
induction model: ``tip_loss``, ``momentum_balance``) is weighed against all the round's significant
model-form candidates fitted together, not against one of them: on lifting-line data with a fast
wake and rotational augmentation in the polars the effect explained 45-51 % of what ``tip_loss``
alone leaves but 83-96 % of what ``tip_loss`` and ``momentum_balance`` together leave, against
47-59 % for the best physical candidate on the same code's control (2026-11-28, seeds 26000-26004).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from calib.diagnosis.model_form import MODEL_FORM_COLLINEARITY, model_form_r2, not_separable
from calib.diagnosis.result import CandidateFit
from calib.diagnosis.share import share_record, share_test
from calib.words import p_is

#: At most this many physical effects (the best variant of each, by BIC) are fitted on top of the
#: model form when one beats a significant model-form candidate [-].
OVER_FORM_EFFECTS = 4


def chi2_of(namer, values: np.ndarray) -> float:
    """χ² of model outputs ``values`` against the namer's measurements (σ and the tolerance) [-]."""
    ok = np.isfinite(values).all(axis=1)
    return float(np.sum(((namer.meas.values - values) / namer.meas.sigma)[ok] ** 2))


def over_model_form(namer, round_no: int, rnd: dict, best: CandidateFit, forms: list, fits: list,
                    share: float, fit_task) -> CandidateFit:
    """A physical candidate when one earns its place on top of the round's significant model-form
    candidates ``forms`` (all fitted jointly), else the best of ``forms`` (``rnd`` says why).

    The significant physical candidates (the best variant of each effect, ``best`` and up to
    :data:`OVER_FORM_EFFECTS` effects by BIC) are each fitted on top of the joint model form; one
    whose parameters all correlate with it at R² ≥ :data:`MODEL_FORM_COLLINEARITY` is not separable
    and left out; when that is ``best`` and no effect is named yet, ``best`` is named if it explains
    ``share`` of what the best model-form candidate alone leaves (the rule before the joint model
    form: in family the true wind-speed scale or blockage is collinear with ``momentum_balance``,
    R² 0.86-0.94, and a small one is absorbed by the joint model form); else the best of the
    others by BIC is named when it explains ``share`` of what the joint model form leaves beyond the
    noise and the model-form tolerance (χ² − dof). After a physical effect, none is named when the
    model with the joint model form already passes the global χ² test at ``significance`` (the share
    of so small a misfit is noise: χ² − dof scatters by √(2 dof)). A physical candidate named here is kept in
    ``namer._over_form`` (it skips the later-effect share test). ``fit_task`` fits one candidate
    (:func:`calib.diagnosis.naming.fit_task`).
    """
    form = forms[0]                                  # fits are sorted by BIC: the best model form
    joint = _joint_form(namer, round_no, forms, fit_task)
    if joint is None:
        return best
    base, n_base, names, chi2_form = joint
    dof_form = namer.n_res - n_base
    p_form = float(stats.chi2.sf(chi2_form, dof_form))
    head = (f"{form.name}: Λ = {form.lr_statistic:.4g} for {form.n_params} parameter(s), {p_is(form.p_value)}; "
            f"effect {form.effect_text}; {best.name} fits better (ΔBIC = {form.bic - best.bic:.3g}), but ")
    on_top = _on_top(namer, round_no, best, fits, base, n_base, names, fit_task)
    if not on_top:
        return best
    apart = [t for t in on_top if not_separable(t[3], best, [names]) is None]
    first = next((t for t in on_top if t[1] == best.name), None)
    single, single_args = (_single_form_share(namer, round_no, best, form, share, fit_task)
                           if not namer.named and first is not None and first not in apart else (None, ()))
    if single is not None:
        rnd.setdefault("shares", []).append(share_record(best.name, best.effect, *single_args, "point", single))
        single = single if single.share >= share else None
    if single is not None:
        # the first effect, not separable from the joint model form: judged against the best model-form
        # candidate alone (in family the true wind-speed scale and blockage, R² 0.86-0.94 with momentum_balance)
        rnd["reason"] += (f"; not separable from {names} together, but on top of {form.name} alone it explains "
                          f"{_percent(single.share)} ± {_percent(single.sd)} of the misfit {form.name} leaves (at least "
                          f"{100 * share:.0f} % names it)")
        return best
    after_effect = any(namer.family.kind(n) != "model_form" for n in namer.named)
    if after_effect and p_form >= namer.dset.significance:
        rnd.update(verdict=form.effect, reason=head + (
            f"with {' + '.join(namer.named + [names])} (model form {names}, all fitted jointly) the model is "
            f"consistent with the noise and the model-form tolerance (χ²/dof {chi2_form / dof_form:.3g}, "
            f"{p_is(p_form)} ≥ significance {namer.dset.significance:g}): the misfit is the model's form, not "
            f"{best.effect}"))
        return form
    tests = {t[1]: share_test(chi2_form - t[2], t[4], chi2_form, dof_form, share, namer.dset.significance,
                              len(on_top)) for t in on_top}
    said = _shares_said(namer, names, chi2_form, on_top, apart, tests)
    if apart:
        lab = apart[0][1]
        rnd.setdefault("shares", []).append(share_record(
            lab, next(f.effect for f in fits if f.name == lab), chi2_form - apart[0][2], apart[0][4], chi2_form,
            dof_form, len(on_top),
            "point", tests[lab]))
    if apart and tests[apart[0][1]].share >= share:
        winner = next(f for f in fits if f.name == apart[0][1])
        if winner is not best:
            rnd.update(verdict=winner.effect, reason=(
                f"{winner.name}: Λ = {winner.lr_statistic:.4g} for {winner.n_params} parameter(s), "
                f"{p_is(winner.p_value)}; effect {winner.effect_text}; {best.name} fits better alone "
                f"(ΔBIC = {winner.bic - best.bic:.3g}), but on top of the model form {winner.name} fits best"))
        rnd["reason"] += f"; {said}"
        namer._over_form = winner
        return winner
    rnd.update(verdict=form.effect, reason=head + (
        f"{said}; none separable from it explains {100 * share:.0f} %: the misfit is the model's form, not "
        f"{best.effect}"))
    return form


def _shares_said(namer, names: str, chi2_form: float, on_top: list, apart: list, tests: dict) -> str:
    """The shares of the misfit left by the joint model form ``names`` that the candidates ``on_top``
    explain, in words (with R², the ones left out as not separable, the best separable one's spread)."""
    said = "; ".join(f"{lab} {_percent(tests[lab].share)}" + (
        f" (R² {float(np.min(r2)):.2f} with the model form)" if r2 is not None and len(r2) else "")
                     for _, lab, _, r2, _ in on_top)
    said = (f"on top of {' + '.join(namer.named + [names])} (model form {names}, all fitted jointly: χ² "
            f"{chi2_form:.4g}), of the misfit left beyond the noise and the model-form tolerance the physical "
            f"candidates explain: {said}")
    tied = [t[1] for t in on_top if t not in apart]
    if tied:
        said += (f"; {', '.join(tied)} not separable from the model form (R² ≥ {MODEL_FORM_COLLINEARITY:g} "
                 "for every parameter): left out")
    if apart:
        top = tests[apart[0][1]]
        said += f"; {apart[0][1]}, the best separable: {_percent(top.share)} ± {_percent(top.sd)}"
    return said


def _percent(share: float) -> str:
    return "all" if not np.isfinite(share) else f"{100 * share:.0f} %"


def _joint_form(namer, round_no: int, forms: list, fit_task):
    """(base effects with ``forms`` added, their parameter count, the forms' names, χ² of the joint
    fit), or None when the joint fit failed."""
    base = namer.base_effects
    for f in forms:
        base = namer.family.add(base, f)
    n_base = namer.family.n_parameters(base)
    names = " + ".join(f.name for f in forms)
    if len(forms) == 1:
        return base, n_base, names, forms[0].chi2
    n_before = namer.family.n_parameters(namer.base_effects)
    out = fit_task({"name": names, "measurements": namer.meas, "settings": namer.known,
                    "own": list(range(n_before, n_base)),
                    "model": namer.wrap(namer.family.candidate_model(base[:-1], base[-1]),
                                        f"round {round_no + 1}: {names} (model form, jointly)")})
    return None if "error" in out else (base, n_base, names, chi2_of(namer, out["values"]))


def _on_top(namer, round_no: int, best: CandidateFit, fits: list, base: list, n_base: int, names: str,
            fit_task) -> list:
    """[(BIC, label, χ², R² with the model form or None, parameter count)] of the physical candidates
    fitted on top of ``base`` (the joint model form), sorted by BIC."""
    physical = [best] + [f for f in fits if f.kind == "physical" and f.significant and f.effect != best.effect]
    labels, seen = [], set()
    for f in physical:
        if f.effect not in seen and len(labels) < OVER_FORM_EFFECTS:
            seen.add(f.effect)
            labels.append(f.name)
    tasks = [{"name": f"{lab} over {names}", "measurements": namer.meas, "settings": namer.known,
              "own": list(range(n_base, n_base + len(namer._effects[lab].parameters()))),
              "model": namer.wrap(namer.family.candidate_model(base, namer._effects[lab]),
                                  f"round {round_no + 1}: {lab} over {names}")} for lab in labels]
    outs = namer.executor.map(fit_task, tasks, None)
    kinds = [(e.parameters(), namer.family.kind(e.name)) for e in base]
    on_top = []
    for lab, task, out in zip(labels, tasks, outs):
        if "error" in out:
            continue
        chi2 = chi2_of(namer, out["values"])
        corr = getattr(getattr(out["result"], "identifiability", None), "correlation", None)
        on_top.append((chi2 + len(task["own"]) * np.log(namer.n_res), lab, chi2,
                       model_form_r2(corr, kinds, task["own"]), len(task["own"])))
    return sorted(on_top, key=lambda t: t[0])


def _single_form_share(namer, round_no: int, best: CandidateFit, form: CandidateFit, share: float,
                       fit_task) -> tuple:
    """The share test (:func:`calib.diagnosis.share.share_test`) of ``best`` on top of ``form`` (one
    model-form candidate): of the misfit the model with ``form`` leaves beyond the noise and the
    tolerance, does ``best`` explain ``share``? With the test's arguments (Λ, k, χ², dof, candidates);
    (None, ()) when the fit fails."""
    base = namer.family.add(namer.base_effects, form)
    n_base = namer.family.n_parameters(base)
    effect = namer._effects[best.name]
    out = fit_task({"name": f"{best.name} over {form.name}", "measurements": namer.meas, "settings": namer.known,
                    "own": list(range(n_base, n_base + len(effect.parameters()))),
                    "model": namer.wrap(namer.family.candidate_model(base, effect),
                                        f"round {round_no + 1}: {best.name} over {form.name}")})
    if "error" in out:
        return None, ()
    args = (form.chi2 - chi2_of(namer, out["values"]), len(effect.parameters()), form.chi2, namer.n_res - n_base, 1)
    return share_test(*args[:4], share, namer.dset.significance), args
