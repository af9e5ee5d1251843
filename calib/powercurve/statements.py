"""What a power curve's report says about its inputs: :func:`posterior_statement` (what the draws stand
for and what the calibration's uncertainty leaves out) and :func:`schedule_warnings` (what the schedule
could not do at the central curve)."""

from __future__ import annotations

import numpy as np

from calib.powercurve.schedule import ScheduledCurve

__all__ = ["delta_statement", "posterior_statement", "sampling_statement", "schedule_warnings"]


def posterior_statement(result) -> list[str]:
    """What the draws stand for, by estimator, and what the calibration's uncertainty leaves out.

    The MAP estimator's covariance is a Laplace posterior. The truncated estimator has no posterior:
    its covariance is the data's in the retained directions plus the prior's in the frozen ones
    (:func:`calib.calibration.identifiability.frozen_aware_covariance`); the statement says so, how
    much of the variance the prior carries, and which terms the result does not record (the field
    between the nodes without a gain, the frozen directions' curvature term when not sampled).
    """
    unc = result.uncertainty
    est = result.estimator
    if est == "map":
        out = [f"estimator {est!r}: the draws and the delta method use its Laplace posterior covariance "
               "(result.uncertainty.cov_p)"]
    else:
        cov = np.asarray(unc.cov_p, float)
        frozen = np.asarray(unc.cov_frozen, float)
        total = float(np.trace(cov))
        share = float(np.trace(frozen)) / total if frozen.shape == cov.shape and total > 0 else float("nan")
        out = [f"estimator {est!r} has no posterior: the draws and the delta method use its recorded covariance, the "
               "data's in the retained directions plus the prior's in the frozen ones (result.uncertainty.cov_p)"
               + (f"; the prior carries {100 * share:.0f} % of its variance (trace)" if np.isfinite(share) else "")]
    left = []
    if not np.asarray(unc.gain).size:
        left.append("the correction field between and beyond the nodes (the result records no gain)")
    if unc.curvature and not unc.curvature.get("samples", 0):
        left.append("the frozen directions' curvature term (not sampled)")
    if getattr(unc, "aliasing_note", ""):
        left.append(f"({unc.aliasing_note})")
    if left:
        out.append("left out of the calibration's uncertainty: " + "; ".join(left))
    return out


def schedule_warnings(schedule, central: ScheduledCurve) -> list[str]:
    """Sentences on what a variable-speed schedule could not do at the central curve: rated power
    never reached in the bins, or the rotor at its maximum speed from the first bin (a speed limit
    below what region 2 asks at the lowest wind speed)."""
    out = []
    if getattr(schedule, "kind", "") != "variable_speed":
        return out
    ok = central.ok
    if ok.any() and not np.any(central.region == 3):
        out.append(f"the calibrated rotor does not reach rated power ({schedule.rated_power / 1e6:.4g} MW) in any bin "
                   f"up to {central.wind_speed[ok][-1]:g} m/s (at most {np.nanmax(central.power) / 1e6:.4g} MW): "
                   "every bin stays in region 2")
    if ok.any() and central.rotor_speed[ok][0] >= schedule.max_rotor_speed - 1e-9:
        out.append(f"the rotor is at its maximum speed {schedule.max_rotor_speed:g} rpm from the first bin "
                   f"({central.wind_speed[ok][0]:g} m/s): the speed limit is below what the tip-speed ratio asks there")
    return out


def capped_bins(pc) -> np.ndarray:
    """Bins where rated-power capping acts within the draws: some draws pitch to hold rated power there
    (pitch above the schedule's fine pitch) and some do not (bool, shape (n_bins,)); none for a
    schedule without a fine pitch (fixed speed, table)."""
    fine = getattr(pc.schedule, "fine_pitch", None)
    pitch = pc.draws.get("pitch")
    if fine is None or pitch is None or pitch.shape[0] == 0 or getattr(pc.schedule, "kind", "") != "variable_speed":
        return np.zeros(pc.wind_speed.size, bool)
    ok = np.isfinite(pitch)
    up = ok & (pitch > float(fine) + 1e-6)
    return np.any(up, axis=0) & np.any(ok & ~up, axis=0)


def delta_statement(pc, row) -> str:
    """Whether the delta method's AEP 1-σ of the calibration is within 10 % of the draws' (or twice the
    draws' own scatter, 1/√(2(N−1))) at the AEP table row ``row``, and where it is not, why.

    Two causes are tested, from the draws themselves: a curvature of the power in the parameters
    (a linear map keeps the draws' mean AEP at the central curve's; a mean more than 3 standard
    errors σ/√N away says the map is curved: a variable-speed schedule runs region 2 at the maximum
    of C_P over λ, where any parameter move that acts like a change of λ or pitch lowers the power
    to second order, which the linearization misses) and rated-power capping (bins where some draws
    reach rated power and others do not, :func:`capped_bins`); and draws clipped to a bound."""
    sd, dl, n = row["sigma_mwh"].get("calibration (draws)"), row.get("sigma_calibration_delta_mwh"), row["draws_used"]
    if n < 3 or not (np.isfinite(sd) and np.isfinite(dl) and sd > 0):
        return ""
    scatter = 1.0 / np.sqrt(2.0 * (n - 1))
    limit = max(0.1, 2.0 * scatter)
    ratio = dl / sd
    head = f"At {row['distribution']} the delta method's AEP σ is {ratio:.2f} × the draws'"
    if abs(ratio - 1.0) <= limit:
        return f"{head}, within {100 * limit:.0f} %."
    why = []
    shift = row["draws_mean_aep_mwh"] - row["p50_mwh"]
    se = sd / np.sqrt(n)
    if abs(shift) > 3.0 * se:
        region2 = getattr(pc.schedule, "kind", "") == "variable_speed" and shift < 0
        why.append(f"the power is curved in the parameters: the draws' mean AEP lies {shift:+.3g} MWh from the central "
                   f"curve's ({abs(shift) / se:.0f} standard errors; a linear map keeps it there)"
                   + (", the schedule running region 2 at the maximum of C_P over λ, where a parameter move lowers "
                      "the power to second order" if region2 else ""))
    capped = capped_bins(pc)
    if capped.any():
        v = pc.wind_speed[capped]
        where = f"{v.min():g}" if v.min() == v.max() else f"{v.min():g}–{v.max():g}"
        why.append(f"rated-power capping: at {where} m/s some draws reach rated power and others do not")
    if pc.n_clipped:
        why.append(f"{pc.n_clipped} draws were clipped to a parameter bound")
    if not why:
        why.append(f"neither a curvature of the draws' mean nor rated-power capping was found (the draws' σ scatters by "
                   f"±{100 * scatter:.0f} % with {n} draws)")
    return f"{head}, more than {100 * limit:.0f} % off: " + "; ".join(why) + "."


def sampling_statement(row: dict) -> str:
    """The AEP table row's sampling σ beside its posterior σ, in words (:mod:`calib.powercurve.sampling`): the
    P50 ± 1.645 σ_total interval is the posterior's (a truth drawn from the prior); over repeated measurements
    of one turbine the calibrated AEP itself spreads by the sampling σ, which leaves out the prior's shrinkage,
    the field between the nodes and the model discrepancy (a bias at a fixed truth, not a spread)."""
    ss = row.get("sigma_calibration_sampling_mwh", float("nan"))
    if not np.isfinite(ss):
        return ""
    return (f"At {row['distribution']} the interval P50 ± 1.645 σ is the posterior's (Bayesian: for a truth drawn from "
            f"the calibration's prior); repeated measurements of the same turbine would spread the calibrated AEP by "
            f"{ss:.3g} MWh (1-σ, the estimate's sampling σ, noise only: frequentist, without the bias the prior, the "
            f"field between the nodes and the model form leave at a fixed truth), against the posterior calibration "
            f"σ of {row['sigma_calibration_delta_mwh']:.3g} MWh (delta method).")
