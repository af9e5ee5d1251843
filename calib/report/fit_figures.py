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
from matplotlib.collections import LineCollection
from matplotlib.patches import Rectangle

from calib.calibration.result import CalibrationResult
from calib.report.panels import (Margins, lean_ticks, panel_grid, plain_numbers, settle_labels, title_height,
                                 unit_prefix, wrap_title)

ROTOR_SPEED_VARIATION = 0.01   # relative spread [-] above which the rotor speed "varies"
MAX_PITCH_LINES = 8            # join model points of equal pitch when there are at most this many pitches
PANEL_SIZE = (3.6, 2.2)        # main panel of a channel [in]
STRIP_HEIGHT = 1.0             # residual strip under it [in]


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
    model = result.fit.model_after if which == "after" else result.fit.model_before
    status = result.fit.status_after if which == "after" else result.fit.status_before
    r = (result.fit.measured - model) / result.fit.sigma
    return np.where((status == 0)[:, None], r, np.nan)


def plot_fit(result: CalibrationResult):
    """Measured vs model before and after calibration per channel, each over its residual strip.

    Returns
    -------
    matplotlib.figure.Figure
        One axes per channel (in channel order). The residual strip under each is drawn in
        that axes' coordinates below its plotting area (x in data, y in axes fraction
        ``[-(g + s), -g]``) instead of in an axes of its own, which would double the
        figure's most expensive part; its points carry the gid ``"residual:<k>"`` and the
        x-axis label the gid ``"xlabel"``.
    """
    x, xlabel, reason = fit_abscissa(result)
    nc = len(result.channels)
    ncol = min(3, nc)
    nrow = int(np.ceil(nc / ncol))
    pitch = np.asarray(result.conditions.get("pitch", np.zeros_like(x)), float)
    groups = _pitch_groups(x, pitch)
    lines = " (lines join points of equal pitch)" if groups else ""
    w, h = PANEL_SIZE
    gap, strip, below = 0.08, STRIP_HEIGHT, 0.5           # [in]: under each main panel
    margins = Margins(left=0.85, right=0.2, bottom=gap + strip + below, top=0.7, wgap=0.85,
                      hgap=gap + strip + below + 0.3)
    width = margins.left + ncol * w + (ncol - 1) * margins.wgap + margins.right
    title = wrap_title(f"{result.name}: measured vs model before and after calibration, against "
                       f"{xlabel.split(' [')[0]} ({reason}){lines}; under each channel: whitened residual after "
                       f"calibration, bands ±1 and ±2", width, 9)
    fig, axes = panel_grid(nrow, ncol, PANEL_SIZE, replace(margins, top=title_height(title, 9) + 0.3), n_panels=nc)
    fig.suptitle(title, fontsize=9, y=1 - 0.06 / fig.get_size_inches()[1])
    okb, oka = result.fit.status_before == 0, result.fit.status_after == 0
    res_after = whitened_residual(result, "after")
    gof = result.goodness_of_fit()["per_channel"]
    span = float(np.ptp(x)) or 1.0
    xlo, xhi = float(np.min(x)) - 0.04 * span, float(np.max(x)) + 0.04 * span
    g, s = gap / h, strip / h                              # strip position in axes fraction
    for k, (ch, unit) in enumerate(zip(result.channels, result.channel_units)):
        ax = axes[k // ncol, k % ncol]
        div, unit = unit_prefix(unit, result.fit.measured[:, k])      # 5.1 MW, not 5.1 with "1e6" at the axis end
        ax.errorbar(x, result.fit.measured[:, k] / div, yerr=result.fit.sigma[:, k] / div, fmt=".", color="k", ms=3,
                    lw=0.6,
                    label="measured ±σ")
        ax.plot(x[okb], result.fit.model_before[okb, k] / div, "x", color="C3", ms=4, label="model before")
        ax.plot(x[oka], result.fit.model_after[oka, k] / div, "o", mfc="none", color="C0", ms=4, label="model after")
        for idx in groups:
            idx = idx[oka[idx]]
            ax.plot(x[idx], result.fit.model_after[idx, k] / div, "-", color="C0", lw=0.5, alpha=0.6)
        ax.set_xlim(xlo, xhi)
        lean_ticks(ax)
        plain_numbers(ax)
        ax.set_ylabel(f"{ch} [{unit}]", fontsize=8)
        ax.tick_params(labelsize=7, labelbottom=False)
        ax.grid(True, alpha=0.3)
        ax.set_title(f"{ch}: χ²/point {gof[ch]['chi2_per_point_before']:.3g} → "
                     f"{gof[ch]['chi2_per_point_after']:.3g}", fontsize=8, pad=3, y=1.0)
        if k == 0:
            ax.legend(fontsize=7, loc="best")
        _residual_strip(ax, x, res_after[:, k], ~oka, (xlo, xhi), g, s, k)
        ax.text(0.5, -(g + s) - 0.13, xlabel, transform=ax.transAxes, ha="center", va="top", fontsize=8, gid="xlabel")
    settle_labels(fig)
    return fig


def _residual_strip(ax, x, r, failed, xlim, g: float, s: float, k: int) -> None:
    """Whitened residuals in a strip under ``ax`` (axes fraction y in [-(g + s), -g]), bands ±1 and ±2."""
    lim = max(3.0, 1.15 * float(np.nanmax(np.abs(r)))) if np.isfinite(r).any() else 3.0
    xt = ax.get_xaxis_transform()                          # x in data, y in axes fraction
    y0 = -(g + s)

    def to_strip(v):
        return y0 + s * (np.asarray(v, float) + lim) / (2 * lim)

    xlo, xhi = xlim
    for level, alpha in ((2, 0.08), (1, 0.12)):
        ax.add_patch(Rectangle((xlo, to_strip(-level)), xhi - xlo, to_strip(level) - to_strip(-level), transform=xt,
                               color="C0", alpha=alpha, lw=0, clip_on=False))
    ax.add_patch(Rectangle((xlo, y0), xhi - xlo, s, transform=xt, fill=False, lw=0.8, clip_on=False))
    locs = [t for t in ax.xaxis.get_majorticklocs() if xlo <= t <= xhi]
    labels = ax.xaxis.get_major_formatter().format_ticks(locs)
    grid = [[(t, y0), (t, -g)] for t in locs] + [[(xlo, to_strip(0)), (xhi, to_strip(0))]]
    ax.add_collection(LineCollection(grid, colors=["0.85"] * len(locs) + ["k"], linewidths=[0.6] * len(locs) + [0.6],
                                     transform=xt, clip_on=False))
    marks = [[(t, y0), (t, y0 - 0.02)] for t in locs]
    levels = [v for v in (-2, 0, 2)]
    marks_y = [[(0, to_strip(v)), (-0.012, to_strip(v))] for v in levels]
    ax.add_collection(LineCollection(marks, colors="k", linewidths=0.8, transform=xt, clip_on=False))
    ax.add_collection(LineCollection(marks_y, colors="k", linewidths=0.8, transform=ax.transAxes, clip_on=False))
    for t, label in zip(locs, labels):
        ax.text(t, y0 - 0.03, label, transform=xt, ha="center", va="top", fontsize=7)
    for v in levels:
        ax.text(-0.02, to_strip(v), f"{v:+d}" if v else "0", transform=ax.transAxes, ha="right", va="center",
                fontsize=7)
    ax.text(-0.1, y0 + s / 2, "(meas − after)/σ", transform=ax.transAxes, rotation=90, ha="center", va="center",
            fontsize=7)
    ax.plot(x, to_strip(r), "o", mfc="none", color="C0", ms=3, transform=xt, clip_on=False, gid=f"residual:{k}")
    if failed.any():
        ax.plot(x[failed], to_strip(np.full(failed.sum(), -0.9 * lim)), "v", color="C3", ms=4, transform=xt,
                clip_on=False, label="model failed")
