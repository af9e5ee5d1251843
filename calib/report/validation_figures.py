"""Measured against predicted loads along a campaign's operating points, for a workflow
with measured data: the nominal model, the model with the effects the discrepancy
workflow named, each stage's calibration with its 95 % interval of the model output, and
the leave-one-out predictions with their 95 % prediction intervals (model + noise).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np
from scipy import stats

from calib.calibration.result import CalibrationResult
from calib.report.panels import Margins, lean_ticks, panel_grid, plain_numbers, settle_labels, unit_prefix

STAGE_COLOURS = ("tab:blue", "tab:green", "tab:purple", "tab:brown")
PANEL = (3.4, 2.3)     # one channel's panel [in]


def predict_channels(result: CalibrationResult, model, conditions, confidence: float = 0.95):
    """Any channel of ``model`` at ``result.p_hat`` with the interval of the model output.

    Unlike :meth:`CalibrationResult.predict`, the channels need not be the ones the result was
    calibrated on (e.g. pressure-tap coefficients predicted from a hub-load calibration): the
    variance is g Cov(p̂) gᵀ with g the model's sensitivity at p̂ (same parameters).

    Returns
    -------
    names : list of str
    values, half_width : ndarray, shape (n_points, n_channels)
        Prediction and half-width of the interval [channel units]; NaN where the model failed.
    """
    ev, G = model.jacobian(result.estimate.p_hat, conditions)
    var = np.einsum("kcj,jl,kcl->kc", np.nan_to_num(G), result.uncertainty.cov_p, np.nan_to_num(G))
    z = float(stats.norm.ppf(0.5 * (1 + confidence)))
    half = np.where(ev.ok[:, None], z * np.sqrt(np.maximum(var, 0.0)), np.nan)
    values = np.where(ev.ok[:, None], ev.values, np.nan)
    return [c.name for c in model.channels], values, half


def plot_campaign(channels, measured: np.ndarray, wind: np.ndarray, nominal: np.ndarray,
                  with_effects: np.ndarray | None, effect_label: str,
                  stages: Mapping[str, tuple[np.ndarray, np.ndarray]],
                  validations: Mapping[str, object] | None = None, title: str = "", units: Mapping[str, str] | None = None,
                  ncol: int = 2):
    """Measured and modelled channels against wind speed.

    Parameters
    ----------
    channels : sequence of str
        Panels, one per channel.
    measured, nominal : ndarray, shape (n_points, n_channels)
    wind : ndarray, shape (n_points,)
        Wind speed [m/s].
    with_effects : ndarray or None
        The nominal model with the named effects at their fitted values.
    effect_label : str
    stages : mapping stage name -> (values, half_width), each (n_points, n_channels)
        Calibrated predictions with the half-width of their 95 % interval.
    validations : mapping stage name -> calib.workflow.validation.Validation, optional
        Leave-one-out predictions drawn as error bars (prediction intervals).
    units : mapping channel -> unit

    Returns
    -------
    matplotlib.figure.Figure
    """
    units = units or {}
    n = len(channels)
    ncol = min(ncol, n)
    nrow = int(np.ceil(n / ncol))
    n_labels = 2 + (with_effects is not None) + len(stages) * (1 + bool(validations))
    legend_rows = int(np.ceil(n_labels / 3))
    fig, axes = panel_grid(nrow, ncol, PANEL, Margins(left=0.75, right=0.2, bottom=0.55 + 0.2 * legend_rows,
                                                      top=0.65 if title else 0.35, wgap=0.75, hgap=0.75))
    axes = np.atleast_1d(axes).reshape(-1)
    order = np.argsort(wind)
    x = wind[order]
    for j, c in enumerate(channels):
        ax = axes[j]
        div, unit = unit_prefix(units.get(c, ""), measured[:, j])     # kN, not N with "1e3" at the axis end
        ax.plot(x, nominal[order, j] / div, ls="--", color="0.45", lw=1.2, label="nominal 2-D polars")
        if with_effects is not None:
            ax.plot(x, with_effects[order, j] / div, ls=":", color="tab:orange", lw=2.2, zorder=4,
                    label=f"nominal + {effect_label} (fitted)")
        for s, (name, (vals, half)) in enumerate(stages.items()):
            col = STAGE_COLOURS[s % len(STAGE_COLOURS)]
            v, h = vals[order, j] / div, half[order, j] / div
            ax.plot(x, v, color=col, lw=1.4, label=f"calibrated: {name}")
            ax.fill_between(x, v - h, v + h, color=col, alpha=0.18, lw=0)
            val = (validations or {}).get(name)
            if val is not None:
                rows = [r for r in val.rows if r.channel == c and np.isfinite(r.predicted)]
                if rows:
                    g = np.array([r.group for r in rows]) + 0.25 * (s + 1)
                    p = np.array([r.predicted for r in rows]) / div
                    err = np.array([[r.predicted - r.lower for r in rows], [r.upper - r.predicted for r in rows]]) / div
                    ax.errorbar(g, p, yerr=err, fmt="s", ms=3.5, color=col, mfc="white", capsize=2, lw=0.9,
                                label=f"left out ({name}), 95 % PI")
        ax.plot(x, measured[order, j] / div, "o", color="k", ms=4.5, zorder=5, label="measured")
        ax.set_title(f"{c} [{unit}]" if unit else c, fontsize=9)
        ax.set_xlabel("wind speed [m/s]", fontsize=8)
        lean_ticks(ax)
        plain_numbers(ax)
        ax.grid(alpha=0.3)
    for ax in axes[n:]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(3, len(labels)), fontsize=7, frameon=False,
               bbox_to_anchor=(0.5, 0.0))
    if title:
        fig.suptitle(title, fontsize=10)
    settle_labels(fig)
    return fig
