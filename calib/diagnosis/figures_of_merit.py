"""Figures of merit of the diagnosis: the gap between measurements and a model
(:func:`gap`: χ², χ²/dof, p-value, per-channel RMS), where the nominal model disagrees
(:func:`find`: whitened residuals and their trends) and how much a candidate effect changes
the outputs against the model-form tolerance (:func:`effect_size`).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy import stats

#: Points whose |output| is at least this fraction of the channel's largest count in effect sizes.
EFFECT_SIZE_USABLE = 0.1


def effect_size(values: np.ndarray, base: np.ndarray, tolerance: np.ndarray, channels: Sequence[str],
                wind_speed: np.ndarray) -> tuple[float, str, bool]:
    """How much a candidate changes the outputs, against the model-form tolerance.

    Parameters
    ----------
    values, base : ndarray, shape (n_points, n_channels)
        The outputs with the candidate and without it [channel units].
    tolerance : ndarray, shape (n_channels,)
        Relative model-form tolerance per channel [-].
    channels : sequence of str
    wind_speed : ndarray, shape (n_points,)
        Named in the words [m/s].

    Returns
    -------
    size : float
        The largest relative change (values − base) / |base| over the points where |base|
        is at least :data:`EFFECT_SIZE_USABLE` of the channel's largest [-], in the channel
        where it is largest against the tolerance.
    words : str
        E.g. ``"-2.1 % power at 7.3 m/s (tolerance 1 %)"`` (the wind speed of that point).
    exceeds : bool
        Whether that change exceeds the channel's tolerance (always, with tolerance 0 and a
        change).
    """
    best = (-1.0, 0.0, "", 0.0, np.nan)
    for j, c in enumerate(channels):
        b = np.abs(base[:, j])
        ok = np.isfinite(values[:, j]) & np.isfinite(base[:, j]) & (b >= EFFECT_SIZE_USABLE * np.nanmax(b, initial=0))
        ok &= b > 0
        if not ok.any():
            continue
        rel = (values[ok, j] - base[ok, j]) / b[ok]
        k = int(np.argmax(np.abs(rel)))
        score = abs(rel[k]) / tolerance[j] if tolerance[j] > 0 else (np.inf if rel[k] != 0 else 0.0)
        if score > best[0]:
            best = (score, float(rel[k]), c, float(tolerance[j]), float(wind_speed[ok][k]))
    score, rel, c, tol, v = best
    if score < 0:
        return float("nan"), "no usable point", False
    words = f"{100 * rel:+.2g} % {c} at {v:.3g} m/s" + (f" (tolerance {100 * tol:.2g} %)" if tol else "")
    return abs(rel), words, bool(score > 1.0)


def gap(measured: np.ndarray, model: np.ndarray, sigma: np.ndarray, channels: Sequence[str], n_fitted: int = 0) -> dict:
    """χ², χ²/dof (dof = N − n_fitted), p-value and per-channel RMS of measured − model."""
    ok = np.all(np.isfinite(model), axis=1)
    w = (measured[ok] - model[ok]) / sigma[ok]
    chi2 = float(np.sum(w ** 2))
    dof = max(int(w.size) - int(n_fitted), 1)
    rms = {c: float(np.sqrt(np.mean((measured[ok, j] - model[ok, j]) ** 2))) for j, c in enumerate(channels)}
    chi2_ch = {c: float(np.mean(w[:, j] ** 2)) for j, c in enumerate(channels)}
    return {"chi2": chi2, "dof": dof, "chi2_per_dof": chi2 / dof, "p_value": float(stats.chi2.sf(chi2, dof)),
            "rms": rms, "chi2_per_point": chi2_ch, "n_failed": int(np.count_nonzero(~ok))}


def find(measured, model, sigma, conditions: dict, channels, rotor_radius: float) -> dict:
    """Where the nominal model disagrees: whitened residuals and their trends.

    Returns
    -------
    dict
        ``whitened`` (n_points, n_channels) list, per channel the χ²/point and the correlation
        of its whitened residual with tip-speed ratio, pitch, wind speed and load level, and the
        worst points.
    """
    w = (measured - model) / sigma
    lam = conditions["rotor_speed"] * np.pi / 30.0 * rotor_radius / conditions["wind_speed"]
    drivers = {"tip_speed_ratio": lam, "pitch": conditions["pitch"], "wind_speed": conditions["wind_speed"]}
    trends = {}
    for j, c in enumerate(channels):
        ok = np.isfinite(w[:, j])
        row = {"chi2_per_point": float(np.mean(w[ok, j] ** 2)), "mean_whitened": float(np.mean(w[ok, j]))}
        for name, x in {**drivers, "load_level": measured[:, j]}.items():
            xs = x[ok]
            row[f"corr_{name}"] = float(np.corrcoef(xs, w[ok, j])[0, 1]) if np.ptp(xs) > 0 and np.ptp(w[ok, j]) > 0 \
                else 0.0
        trends[c] = row
    order = np.argsort(-np.abs(np.nan_to_num(w)), axis=None)[:5]
    worst = [{"point": int(k // w.shape[1]), "channel": channels[int(k % w.shape[1])],
              "whitened_residual": float(w.flat[k])} for k in order]
    return {"trends": trends, "worst": worst, "tip_speed_ratio": lam.tolist()}
