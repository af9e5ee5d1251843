"""The verdict of a naming round (docs/theory.md, Diagnosis): which candidate effect
the round names, or ``none``, or ``ambiguous`` with the measurement that would tell the two
rivals apart (:func:`judge_round`), and the reason in words.

The best significant candidate (by BIC) is named unless another significant candidate of a
different effect is within ``ambiguity_bic`` of its BIC; then the one whose pattern agrees
better with the localized correction is named, by at least ``ambiguity_pattern``, else the
round is ``ambiguous``.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from calib.diagnosis.ranking import set_bic_weights
from calib.diagnosis.result import CandidateFit
from calib.diagnosis.settings import DiagnosisSettings
from calib.words import p_is


def judge_round(fits: list[CandidateFit], base_chi2: float, base_names: list, dset: DiagnosisSettings,
                separate: Callable[[CandidateFit, CandidateFit], dict]) -> tuple[dict, CandidateFit | None]:
    """A naming round's record and the candidate it names.

    Parameters
    ----------
    fits : list of CandidateFit
        The round's fitted candidates; their BIC weights are set and they are sorted by BIC,
        in place.
    base_chi2 : float
        χ² of the model without them [-] ("none" in the BIC weights).
    base_names : list of str
        The effects named in the earlier rounds (the round's ``base``).
    dset : DiagnosisSettings
        ``significance``, ``ambiguity_bic`` and ``ambiguity_pattern``.
    separate : callable(CandidateFit, CandidateFit) -> dict
        The measurement that would tell two candidates apart (``{"text": ...}``, e.g.
        :func:`calib.diagnosis.naming.separation_of`), asked only for an ``ambiguous`` verdict.

    Returns
    -------
    record : dict
        ``base``, ``candidates``, ``verdict`` (an effect, ``none`` or ``ambiguous``) and
        ``reason`` in words; with ``ambiguous`` (the two effects) and ``separate`` when ambiguous.
    named : CandidateFit or None
        The candidate named (None for ``none`` and ``ambiguous``).
    """
    set_bic_weights(fits, base_chi2)
    fits.sort(key=lambda f: f.bic)
    rnd = {"base": base_names, "candidates": fits}
    sig = [f for f in fits if f.significant]
    if not sig:
        rnd.update(verdict="none", reason=_nothing_significant(fits, dset))
        return rnd, None
    best = sig[0]
    stand_in, passed = "", ""
    if _switched_off_at_bound(best):
        # the fit pins a parameter on the bound where the effect is off (its nominal) and pushes past
        # it: the data want the effect reversed there (erosion that wants a drag decrease), so it
        # stands in for another effect; a significant candidate of another effect whose parameters
        # are all inside their bounds is named before it
        inside = [f for f in sig if f.effect != best.effect and not f.at_bound]
        if inside:
            stand_in = (f"; {best.name} fits better (ΔBIC = {inside[0].bic - best.bic:.3g}) but only with "
                        f"{best.bound_phrase()}, where that effect is off: it stands in for another effect")
            passed, best = best.effect, inside[0]
    # variants of the same effect are not rivals: the best variant names the effect
    rivals = [f for f in sig if f is not best and f.bic - best.bic < dset.ambiguity_bic
              and f.effect not in (best.effect, passed)]
    pattern_note = ""
    if rivals:
        rival = rivals[0]
        a, b = best.pattern_agreement, rival.pattern_agreement
        close = f"{best.effect} and {rival.effect} fit about equally well (ΔBIC = {rival.bic - best.bic:.3g} < " \
                f"{dset.ambiguity_bic:g})"
        if np.isfinite(a) and np.isfinite(b) and abs(a - b) >= dset.ambiguity_pattern:
            # the information criterion cannot tell them apart, the pattern can
            best, other = (best, rival) if a > b else (rival, best)
            pattern_note = (f"; {close}, but the pattern of {best.effect} agrees better with the localized "
                            f"correction ({best.pattern_agreement:.2f} against {other.pattern_agreement:.2f}, "
                            f"a difference of at least {dset.ambiguity_pattern:g})")
        else:
            separation = separate(best, rival)
            rnd.update(verdict="ambiguous", ambiguous=[best.effect, rival.effect], separate=separation, reason=(
                f"{close} and their patterns agree equally with the localized correction ({a:.2f} and {b:.2f}): "
                f"the data cannot tell them apart; {separation['text']}"))
            return rnd, None
    nxt = next((f for f in fits if f is not best), None)
    rnd.update(verdict=best.effect, reason=(
        f"{best.name}: Λ = {best.lr_statistic:.4g} for {best.n_params} parameter(s), {p_is(best.p_value)}; "
        f"BIC weight {best.weight:.3f}; next {nxt.name if nxt else 'none'} ΔBIC = "
        f"{(nxt.bic - best.bic) if nxt else float('inf'):.3g}; pattern agreement with the localized correction "
        f"{best.pattern_agreement:.2f}; effect {best.effect_text}" + bound_suffix(best) + pattern_note
        + stand_in))
    return rnd, best


def _switched_off_at_bound(fit: CandidateFit) -> bool:
    """Whether a parameter of ``fit`` sits on a bound that is also its nominal (the value that
    switches the effect off in that parameter)."""
    return any(q.get("at_bound") and q[q["at_bound"]] == q["nominal"] for q in fit.parameters)


def _nothing_significant(fits: list[CandidateFit], dset: DiagnosisSettings) -> str:
    """The reason of a ``none`` verdict: the best candidate's likelihood ratio, and the one that
    would be significant by it but stays within the model-form tolerance, if any."""
    small = [f for f in fits if f.p_value < dset.significance / max(len(fits), 1) and not f.significant]
    tail = (f"; {small[0].name} would be significant by likelihood ratio, but its change of the outputs "
            f"({small[0].effect_text}) is within the model-form tolerance" if small else "")
    return (f"no candidate improves the fit significantly (likelihood ratio at family-wise level "
            f"{dset.significance:g}); best {fits[0].name}: Λ = {fits[0].lr_statistic:.3g}, "
            f"{p_is(fits[0].p_value)}" + bound_suffix(fits[0]) + tail)


def bound_suffix(fit: CandidateFit) -> str:
    """"; <fit's parameters at a bound>, ..." for a verdict ("" when none is at a bound)."""
    phrase = fit.bound_phrase()
    return (f"; {phrase}: the fit pushed against the bound, so the value is the bound, not an estimate (the "
            f"effect may stand in for another one, or the data hold a gross error)") if phrase else ""
