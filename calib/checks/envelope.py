"""Whether a predicted point lies where the calibration's data were (docs/theory.md, Predictions).

A calibrated model is trusted where its data were: at tip-speed ratios, pitch angles and wind
speeds inside the ranges of the calibration's operating points, and where each blade
station meets angles of attack the calibration's points reached there (the (α, η) the fit
was informed on; :attr:`calib.calibration.result_parts.Fit.alpha_seen`). A predicted point
outside either is an extrapolation: :func:`envelope_of` says which way, per point, in words
an engineer reads ("λ 12.3 above 10.5; 4 of 17 stations at α outside the calibrated range").
"""

from __future__ import annotations

import numpy as np

#: Angles of attack within this margin of a station's calibrated range count as inside [deg].
ALPHA_MARGIN_DEG = 0.5
#: Relative margin on the operating ranges (round-off of conditions read back from files) [-].
RANGE_MARGIN = 1e-6


def _ranges(alpha_seen: np.ndarray, eta_seen: np.ndarray) -> dict:
    """Station η -> (α min, α max) [deg] of the calibration's sections."""
    out = {}
    for e in np.unique(np.round(eta_seen, 9)):
        a = alpha_seen[np.isclose(eta_seen, e, rtol=0, atol=1e-9)]
        out[float(e)] = (float(a.min()), float(a.max()))
    return out


def envelope_of(calibration: dict, radius: float, conditions: dict, alpha_deg=None, eta=None,
                alpha_seen=None, eta_seen=None) -> list[str]:
    """Per predicted point: "" inside the calibration envelope, else what lies outside.

    Parameters
    ----------
    calibration : dict
        The calibration's conditions (``wind_speed`` [m/s], ``rotor_speed`` [rpm], ``pitch``
        [deg] arrays).
    radius : float or None
        Rotor radius [m] (tip-speed ratio; without it the λ range is not checked).
    conditions : dict
        The prediction's conditions, same keys.
    alpha_deg : ndarray, shape (n_points, n_stations), optional
        Angles of attack at the predicted points [deg] (NaN where a station carries no load).
    eta : ndarray, shape (n_stations,), optional
        Their stations r/R [-].
    alpha_seen, eta_seen : ndarray, optional
        The (α [deg], η [-]) the calibration's converged points reached.

    Returns
    -------
    list of str
        One entry per point: "" (inside), or the reasons joined with "; ".
    """
    def lam(c):
        return np.asarray(c["rotor_speed"], float) * np.pi / 30.0 * radius / np.asarray(c["wind_speed"], float)

    drivers = {} if not radius else {"λ": (lam(calibration), lam(conditions), "", "{:.3g}")}
    drivers |= {"pitch": (np.asarray(calibration["pitch"], float), np.asarray(conditions["pitch"], float), " deg",
                         "{:.3g}"),
               "wind speed": (np.asarray(calibration["wind_speed"], float), np.asarray(conditions["wind_speed"], float),
                              " m/s", "{:.3g}")}
    n = len(np.asarray(conditions["wind_speed"]))
    reasons: list[list[str]] = [[] for _ in range(n)]
    for name, (cal, new, unit, fmt) in drivers.items():
        lo, hi = float(np.min(cal)), float(np.max(cal))
        tol = RANGE_MARGIN * max(abs(lo), abs(hi), 1.0)
        for k in np.flatnonzero(new < lo - tol):
            reasons[k].append(f"{name} {fmt.format(new[k])}{unit} below {fmt.format(lo)}{unit}")
        for k in np.flatnonzero(new > hi + tol):
            reasons[k].append(f"{name} {fmt.format(new[k])}{unit} above {fmt.format(hi)}{unit}")
    if alpha_deg is not None and eta is not None and alpha_seen is not None and np.size(alpha_seen):
        ranges = _ranges(np.asarray(alpha_seen, float), np.asarray(eta_seen, float))
        a = np.asarray(alpha_deg, float)[:n]
        eta = np.asarray(eta, float)
        # each station's calibrated α range (NaN for a station the calibration did not load)
        span = np.array([ranges[min(ranges, key=lambda s: abs(s - e))] if any(abs(e - s) <= 1e-9 for s in ranges)
                         else (np.nan, np.nan) for e in eta]).reshape(-1, 2)
        lo, hi = span[:, 0], span[:, 1]
        loaded = np.isfinite(a) & np.isfinite(lo)
        beyond = np.maximum(lo - a, a - hi)                  # > 0 outside the range [deg]
        out = loaded & (beyond > ALPHA_MARGIN_DEG)
        for k in np.flatnonzero(out.any(axis=1)):
            worst = int(np.argmax(np.where(out[k], beyond[k], -np.inf)))
            reasons[k].append(f"{int(out[k].sum())} of {int(loaded[k].sum())} stations at α outside the calibrated "
                              f"range (r/R {eta[worst]:.2f}: α {a[k, worst]:.3g} deg, calibrated {lo[worst]:.3g} to "
                              f"{hi[worst]:.3g} deg)")
    return ["; ".join(r) for r in reasons]
