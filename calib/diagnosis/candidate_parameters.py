"""A candidate's fitted parameters: which bound one sits on (:func:`bound_side`), their rows
in the candidate table (:func:`parameter_records`), and the start of a second fit for the
parameters that never left their start (:func:`away_start`).
"""

from __future__ import annotations

import numpy as np

#: A fitted parameter is "at bound" when it lies within this fraction of its scale of a bound
#: (or beyond it by round-off): the rule of :func:`calib.calibration.identifiability.parameter_verdicts`.
AT_BOUND_TOLERANCE = 1e-3

#: An own parameter of a candidate that ends within this fraction of its scale of its start
#: never left it: the fit is started again away from it (:func:`away_start`).
STUCK_TOLERANCE = 1e-6


def away_start(p: np.ndarray, lower: np.ndarray, upper: np.ndarray, scale: np.ndarray, which) -> np.ndarray:
    """A start one scale away from ``p`` in the parameters ``which``, toward the side with more room.

    Parameters
    ----------
    p, lower, upper, scale : ndarray
        The point a fit ended on, the bounds and the parameters' scales [parameter units].
    which : sequence of int
        The parameters to move (those that never left their start).

    Returns
    -------
    ndarray
        ``p`` with each of ``which`` moved by one scale (at most half the room to the bound it
        moves toward) into the interior: a candidate at zero magnitude, where the derivative
        of a shape parameter (an onset span, a radial exponent) vanishes and Gauss-Newton
        cannot take a step, starts where every parameter acts.
    """
    start = np.array(p, float)
    for j in which:
        up, down = upper[j] - p[j], p[j] - lower[j]
        room = up if up >= down else -down
        start[j] = p[j] + np.sign(room) * min(abs(scale[j]), 0.5 * abs(room))
    return start

def bound_side(value: float, lower: float, upper: float, scale: float,
               tolerance: float = AT_BOUND_TOLERANCE) -> str:
    """Which bound a fitted value sits on: ``"lower"``, ``"upper"`` or ``""`` (neither).

    Parameters
    ----------
    value, lower, upper : float
        The estimate and the parameter's bounds [parameter unit].
    scale : float
        The parameter's scale, a typical meaningful change [parameter unit].
    tolerance : float
        A value within ``tolerance`` × ``scale`` of a bound, or past it (round-off of the
        optimizer's step ends an estimate a few ulp outside), is at that bound [-]. The
        default, 10⁻³ of the scale, is far below any σ a fit gives.
    """
    tol = tolerance * abs(float(scale))
    if value <= lower + tol:
        return "lower"
    if value >= upper - tol:
        return "upper"
    return ""

def parameter_records(res, own: list) -> list[dict]:
    """{name, value, std, unit, nominal, lower, upper, at_bound} of a candidate's own parameters."""
    out = []
    for j in own:
        lo, hi = float(res.estimate.lower[j]), float(res.estimate.upper[j])
        value = float(res.estimate.p_hat[j])
        out.append({"name": res.parameters[j]["name"], "value": value, "std": float(res.uncertainty.std_p[j]),
                    "unit": res.parameters[j]["unit"], "nominal": float(res.estimate.p_nominal[j]), "lower": lo, "upper": hi,
                    "at_bound": bound_side(value, lo, hi, float(res.estimate.scale[j]))})
    return out
