"""The calibration report's summary in sentences (:func:`sentences`): what was retained and why,
the fit, the bands, the prior check, the frozen directions' curvature, the field, the
parameters and the solver, each in words an engineer reads before the tables.
"""

from __future__ import annotations

import numpy as np

from calib.calibration.result import CalibrationResult, fold_sentence, second_start_sentence
from calib.calibration.tightening import sentence as tightening_sentence
from calib.checks.prior_check import PriorCheck
from calib.parametrizations.correction_field import drag_floor_values
from calib.words import p_is


def _prior_limit_clause(r: CalibrationResult) -> str:
    """How the prior limited the automatic choice, from the recorded curve ('' when not recorded)."""
    limit = r.identifiability.truncation.get("prior_limit")
    if limit is None:
        return ""
    limit = int(limit)
    cv = np.asarray(r.identifiability.truncation["cv"], float)
    if limit + 1 < cv.size and np.nanmin(cv[limit + 1:]) < np.nanmin(cv[:limit + 1]):
        return (f"; only the first {limit} directions are determined better by the data than by the prior, "
                f"and the criterion's lower values beyond them ({np.nanmin(cv[limit + 1:]):.3g}) were not taken")
    return f"; the data determine the first {limit} directions better than the prior"


def _bounded_drag_points(pb: dict, cd_min: float | None) -> tuple[int, int] | None:
    """(points of the polar figure where the ΔC_D band starts at the bound C_D,min, all its
    points), or None when there are none (or no bound, no nominal C_D, or a result saved
    before the bounded bands)."""
    if cd_min is None or not {"dcd_lower", "cd0"} <= set(pb):
        return None
    floor = drag_floor_values(pb["cd0"], cd_min)
    cut = np.isclose(np.asarray(pb["dcd_lower"], float), floor, rtol=0.0, atol=1e-12)
    return (int(cut.sum()), int(cut.size)) if cut.any() else None


def sentences(r: CalibrationResult) -> list[str]:
    """Plain statements generated from the numbers they describe."""
    out = _retained_sentences(r)
    out.append(_fit_sentence(r.goodness_of_fit()))
    out += _band_sentences(r)
    out += _prior_check_sentences(r)
    out += _curvature_sentences(r)
    out += _field_sentences(r)
    out += _parameter_sentences(r)
    out += _solver_sentences(r)
    if r.verdict_counts().get("confounded"):
        out.append("A confounded parameter's estimate trades off against the correction field: read it with "
                   "its σ, not as a measurement of that quantity alone.")
    return out


def _retained_sentences(r: CalibrationResult) -> list[str]:
    """How many θ were retained and how they were chosen (cross-validation or the threshold σ̄)."""
    ident = r.identifiability
    if ident.truncation:
        out = [f"The number of retained θ was chosen by {ident.truncation.get('criterion', 'K-fold')} cross-validation "
               f"over operating points (the fewest within one standard error of the minimum): "
               f"{r.n_retained} of {r.n_params} (equivalent σ̄ = {ident.sigma_bar:.3g} scale units; criterion "
               f"{float(np.asarray(ident.truncation['cv'])[r.n_retained]):.3g} against "
               f"{float(np.asarray(ident.truncation['cv'])[0]):.3g} with none retained)"
               + _prior_limit_clause(r) + "."]
        if "second_retained" in ident.truncation:
            out.append(second_start_sentence(ident.truncation))
        return out
    return [(f"{r.n_retained} of {r.n_params} θ have σ(θ) ≤ σ̄ = {ident.sigma_bar:.3g} scale units and were "
             f"estimated; the other {r.n_params - r.n_retained} directions stay at nominal.")]


def _fit_sentence(gof: dict) -> str:
    """χ²/dof before and after calibration with their p-values (``gof``: the result's goodness of fit)."""
    return (f"Before calibration χ²/dof = {gof['chi2_per_dof_before']:.3g} over {gof['dof_before']} residuals "
            f"(nothing fitted, {p_is(gof['p_value_before'])}); after, χ²/dof = "
            f"{gof['chi2_per_dof_after']:.3g} with {gof['dof_after']} degrees of freedom "
            f"({p_is(gof['p_value_after'])}" + ("; the model is consistent with the noise)." if
                                                 gof["p_value_after"] > 0.01 else
                                                 "; the fit is worse than the stated noise explains)."))


def _band_sentences(r: CalibrationResult) -> list[str]:
    """What the bands include and leave out: aliasing, the C_D,min bound, the fit scale."""
    unc, out = r.uncertainty, []
    if unc.aliasing_chi2 > 0:
        out.append(f"A field between the correction nodes of the prior's typical size would add about "
                   f"{unc.aliasing_chi2:.3g} to χ² on average (χ² after here: {r.fit.chi2_after:.3g}); the bands include "
                   f"its effect on the estimate.")
    if unc.aliasing_note:
        out.append(f"Not in the bands: {unc.aliasing_note}")
    bounded = _bounded_drag_points(unc.polar_bands, r.provenance.settings.get("cd_min"))
    if bounded:
        out.append(f"The ΔC_D band starts at C_D,min = {r.provenance.settings['cd_min']:.3g} at {bounded[0]} of the "
                   f"{bounded[1]} points of the polar figure, where the Gaussian band would reach below it: the band "
                   f"is the shortest {100 * float(unc.polar_bands.get('confidence', 0.95)):.0f} % interval of the "
                   f"Gaussian truncated at that bound.")
    if unc.fit_scale > 1.0:
        out.append(f"The covariance of the retained θ is multiplied by χ²/dof = {unc.fit_scale:.3g} (the misfit counts "
                   f"as noise; setting scale_by_fit), so their σ and the data part of every band are "
                   f"{np.sqrt(unc.fit_scale):.3g}× what they would be without it.")
    return out


def _prior_check_sentences(r: CalibrationResult) -> list[str]:
    """The prior check's outcome, why it failed, or that it was not run (none without bands)."""
    unc = r.uncertainty
    if unc.prior_check.get("failed"):
        return [(f"Prior check: could not be computed ({unc.prior_check['failed']}); whether the data support the "
                 f"stated prior was not tested.")]
    if unc.prior_check:
        return [PriorCheck(**unc.prior_check).sentence()]
    if r.provenance.settings.get("prior_check") is False and unc.polar_bands:
        return [("Prior check: not run (prior_check = false): whether the data support the stated prior, which "
                 "sets the width of the bands in the directions the data leave to it, was not tested.")]
    return []


def _curvature_sentences(r: CalibrationResult) -> list[str]:
    """What the frozen directions' prior adds through the model's curvature, or that it was left out."""
    cur = r.uncertainty.curvature
    if cur.get("samples", 0) > 0 and "variance_ratio_mean" in cur:
        return [(f"The frozen directions' prior, propagated through the model's curvature ({cur['used']} of "
                 f"{cur['samples']} draws), adds to the variance of each retained θ on average "
                 f"{cur['variance_ratio_mean']:.2g}× (at most {cur['variance_ratio_max']:.2g}×) its noise part "
                 f"1/s²: the bias a frozen part of the truth gives the estimate where the model is not linear.")]
    if cur.get("samples", None) == 0:
        return [("Not in the bands: curvature_samples = 0, so how the frozen part of the truth biases the retained θ "
                 "where the model is not linear over the prior's range is left out.")]
    return []


def _field_sentences(r: CalibrationResult) -> list[str]:
    """The correction nodes' verdicts counted (none without a correction field)."""
    field = [v for v in r.identifiability.verdicts if v["kind"] in ("lift_correction", "drag_correction")]
    if not field:
        return []
    poor = [v for v in field if v["verdict"] == "poorly observable"]
    moved = [v for v in poor if v["note"]]
    txt = (f"Of {len(field)} correction nodes, {sum(v['verdict'] == 'identified' for v in field)} are identified "
           f"(posterior σ at most {r.provenance.settings.get('identified_ratio', 0.5):g} × prior σ), "
           f"{sum(v['verdict'] == 'at bound' for v in field)} at a bound and {len(poor)} poorly observable: "
           f"their bands stay close to the prior's width")
    txt += (f"; {len(moved)} of these nevertheless moved more than 2σ from nominal (listed below)." if moved
            else ".")
    return [txt]


def _parameter_sentences(r: CalibrationResult) -> list[str]:
    """Each parameter other than the correction nodes: estimate, verdict, shared information, and
    how to tighten it where there is advice."""
    out = []
    for v in r.identifiability.verdicts:
        if v["kind"] in ("lift_correction", "drag_correction"):
            continue
        line = (f"{v['name']} = {v['value']:.4g} ± {v['std']:.2g} {v['unit']} (1σ; prior σ {v['prior_std']:.3g}, "
                f"nominal {v['nominal']:.4g}): {v['verdict']}")
        if "shared_information" in v:
            line += f"; shares {100 * v['shared_information']:.0f} % of its information with the other parameters"
            if v.get("confounded_with"):
                line += f" (most with {v['confounded_with']})"
        out.append(line + ".")
        advice = tightening_sentence(v["name"], (r.identifiability.tightening or {}).get(v["name"], {}), v["unit"])
        if advice:
            out.append(advice)
    return out


def _solver_sentences(r: CalibrationResult) -> list[str]:
    """Failed point evaluations, operating points with several BEM roots, and folds of the solution."""
    out = []
    fail = r.fit.failures
    if fail.get("total_failed_point_evaluations", 0):
        out.append(f"{fail['total_failed_point_evaluations']} point evaluations failed over the run "
                   f"({fail.get('final', 0)} at the estimate); failed points are left out of the cost.")
    n_multi = int(np.count_nonzero(r.fit.multiple_roots)) if r.fit.multiple_roots.size else 0
    if n_multi:
        out.append(f"At {n_multi} operating points the BEM residual has several roots at some station; the "
                   f"root was chosen by the solver's documented rule and those points are flagged.")
    if r.identifiability.fold_directions:
        out.append(fold_sentence(r.identifiability.fold_directions, r.conditions, r.tip_speed_ratio()))
    return out
