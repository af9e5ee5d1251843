"""What a power curve's report says about its inputs: :func:`posterior_statement` (what the draws stand
for and what the calibration's uncertainty leaves out) and :func:`schedule_warnings` (what the schedule
could not do at the central curve)."""

from __future__ import annotations

import numpy as np

from calib.powercurve.schedule import ScheduledCurve

__all__ = ["posterior_statement", "schedule_warnings"]


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
