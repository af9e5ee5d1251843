"""Measured against modelled channels, before and after calibration, with residual panels.

The abscissa follows the data: wind speed when the rotor speed varies between the points
(field data along a control curve, where tip-speed ratio would stack points in one column),
tip-speed ratio λ = ΩR/V when the rotor speed is constant and the radius is known (a
wind-tunnel sweep), wind speed otherwise. Under each channel the whitened residual after
calibration, (measured − model)/σ, is drawn with the ±1 and ±2 bands.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from matplotlib.ticker import MaxNLocator

from calib.report.panels import Margins, lean_ticks, paired_grid, settle_labels, title_height, wrap_title
from calib.result import CalibrationResult

ROTOR_SPEED_VARIATION = 0.01   # relative spread [-] above which the rotor speed "varies"
MAX_PITCH_LINES = 8            # join model points of equal pitch when there are at most this many pitches
PANEL_SIZE = (3.6, 2.2)        # main panel of a channel [in]; its residual panel is 0.45 of its height


def fit_abscissa(result: CalibrationResult) -> tuple[np.ndarray, str, str]:
    """The abscissa of the fit figure.

    Parameters
    ----------
    result : CalibrationResult

    Returns
    -------
    x : ndarray, shape (n_points,)
        Wind speed [m/s] or tip-speed ratio [-].
    label : str
        Axis label with unit.
    reason : str
        Why this abscissa (stated in the figure).
    """
    cond = result.conditions
    wind = np.asarray(cond["wind_speed"], float)
    rpm = np.asarray(cond.get("rotor_speed", np.zeros_like(wind)), float)
    scale = max(float(np.median(np.abs(rpm))), 1e-12)
    if np.ptp(rpm) > ROTOR_SPEED_VARIATION * scale:
        return wind, "wind speed [m/s]", "rotor speed varies between the points"
    lam = result.tip_speed_ratio()
    if lam is None:
        return wind, "wind speed [m/s]", "rotor radius unknown"
    return np.asarray(lam, float), "tip-speed ratio λ = ΩR/V [-]", f"constant rotor speed {np.median(rpm):.4g} rpm"


def _pitch_groups(x: np.ndarray, pitch: np.ndarray) -> list[np.ndarray]:
    """Point indices of equal pitch, sorted by x, when joining them with a line is meaningful."""
    values = np.unique(np.round(pitch, 3))
    if values.size > MAX_PITCH_LINES:
        return []
    groups = []
    for v in values:
        idx = np.flatnonzero(np.round(pitch, 3) == v)
        idx = idx[np.argsort(x[idx])]
        if idx.size < 3 or np.unique(np.round(x[idx], 9)).size < idx.size:
            return []
        groups.append(idx)
    return groups


def whitened_residual(result: CalibrationResult, which: str = "after") -> np.ndarray:
    """(measured − model)/σ per point and channel [-]; NaN where the model failed."""
    model = result.model_after if which == "after" else result.model_before
    status = result.status_after if which == "after" else result.status_before
    r = (result.measured - model) / result.sigma
    return np.where((status == 0)[:, None], r, np.nan)


def plot_fit(result: CalibrationResult):
    """Measured vs model before and after calibration per channel, each over its residual panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    x, xlabel, reason = fit_abscissa(result)
    nc = len(result.channels)
    ncol = min(3, nc)
    nrow = int(np.ceil(nc / ncol))
    pitch = np.asarray(result.conditions.get("pitch", np.zeros_like(x)), float)
    groups = _pitch_groups(x, pitch)
    lines = " (lines join points of equal pitch)" if groups else ""
    margins = Margins(left=0.85, right=0.2, bottom=0.55, top=0.7, wgap=0.85, hgap=0.75)
    width = margins.left + ncol * PANEL_SIZE[0] + (ncol - 1) * margins.wgap + margins.right
    title = wrap_title(f"{result.name}: measured vs model before and after calibration, against "
                       f"{xlabel.split(' [')[0]} ({reason}){lines}; under each channel: whitened residual after "
                       f"calibration, bands ±1 and ±2", width, 9)
    fig, axes = paired_grid(nrow, ncol, PANEL_SIZE, 0.45, replace(margins, top=title_height(title, 9) + 0.3),
                            n_panels=nc)
    fig.suptitle(title, fontsize=9, y=1 - 0.06 / fig.get_size_inches()[1])
    okb, oka = result.status_before == 0, result.status_after == 0
    res_after = whitened_residual(result, "after")
    gof = result.goodness_of_fit()["per_channel"]
    for k, (ch, unit) in enumerate(zip(result.channels, result.channel_units)):
        ax, rax = axes[k // ncol, k % ncol]
        ax.errorbar(x, result.measured[:, k], yerr=result.sigma[:, k], fmt=".", color="k", ms=3, lw=0.6,
                    label="measured ±σ")
        ax.plot(x[okb], result.model_before[okb, k], "x", color="C3", ms=4, label="model before")
        ax.plot(x[oka], result.model_after[oka, k], "o", mfc="none", color="C0", ms=4, label="model after")
        for idx in groups:
            idx = idx[oka[idx]]
            ax.plot(x[idx], result.model_after[idx, k], "-", color="C0", lw=0.5, alpha=0.6)
        lean_ticks(ax)
        rax.yaxis.set_major_locator(MaxNLocator(4, integer=True))
        ax.set_ylabel(f"{ch} [{unit}]", fontsize=8)
        ax.tick_params(labelsize=7, labelbottom=False)
        ax.grid(True, alpha=0.3)
        ax.set_title(f"{ch}: χ²/point {gof[ch]['chi2_per_point_before']:.3g} → "
                     f"{gof[ch]['chi2_per_point_after']:.3g}", fontsize=8, pad=3, y=1.0)
        if k == 0:
            ax.legend(fontsize=6, loc="best")
        r = res_after[:, k]
        lim = max(3.0, 1.15 * float(np.nanmax(np.abs(r)))) if np.isfinite(r).any() else 3.0
        rax.axhspan(-2, 2, color="C0", alpha=0.08, lw=0)
        rax.axhspan(-1, 1, color="C0", alpha=0.12, lw=0)
        rax.axhline(0, color="k", lw=0.6)
        rax.plot(x, r, "o", mfc="none", color="C0", ms=3)
        if (~oka).any():
            rax.plot(x[~oka], np.full((~oka).sum(), -0.9 * lim), "v", color="C3", ms=4, label="model failed")
            rax.legend(fontsize=6, loc="lower right")
        rax.set_ylim(-lim, lim)
        rax.set_ylabel("(meas − after)/σ", fontsize=7)
        rax.set_xlabel(xlabel, fontsize=8)
        rax.tick_params(labelsize=7)
        rax.grid(True, alpha=0.3)
    settle_labels(fig)
    return fig
