"""Figures of the singular-value spectrum and of the truncation choice."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from calib.calibration.result import CalibrationResult
from calib.report.panels import lean_log_ticks, settle_labels, single_panel


def _fig_ax(ax, size=(6.4, 3.6)):
    if ax is None:
        return single_panel(size)
    return ax.figure, ax


def _finish(fig, own: bool):
    """Fix the label positions of a figure made here (not of a caller's)."""
    if own:
        settle_labels(fig, ticklabel_size=10)
    return fig


def plot_singular_values(result: CalibrationResult, ax=None):
    """Singular values s_i of the whitened scaled sensitivities with the cut 1/σ̄.

    Parameters
    ----------
    result : CalibrationResult
    ax : matplotlib Axes, optional
        Draw into it (default: a new figure).

    Returns
    -------
    matplotlib.figure.Figure
    """
    own = ax is None
    fig, ax = _fig_ax(ax)
    s = result.identifiability.singular_values
    i = np.arange(1, s.size + 1)
    keep = result.identifiability.retained
    ax.semilogy(i[keep], np.maximum(s[keep], 1e-16), "o", color="C0", label=f"retained ({keep.sum()})")
    ax.semilogy(i[~keep], np.maximum(s[~keep], 1e-16), "x", color="C3", label=f"frozen ({(~keep).sum()})")
    if np.isfinite(result.identifiability.sigma_bar):
        ax.axhline(1.0 / result.identifiability.sigma_bar, color="k", ls="--", lw=1,
                   label=f"cut 1/σ̄ = {1 / result.identifiability.sigma_bar:.3g}")
    ax.set_xlabel("index i")
    ax.set_ylabel("s_i = 1/σ(θ_i) [1/scale]")
    ax.set_title(f"{result.name}: singular-value spectrum ({result.n_retained} of {s.size} retained)", fontsize=10,
                 y=1.0)
    lean_log_ticks(ax)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, own)


def plot_spectra(results: Mapping[str, CalibrationResult], ax=None):
    """Singular-value spectra of several calibrations (e.g. sensor sets) on one axis.

    Parameters
    ----------
    results : mapping name -> CalibrationResult
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    own = ax is None
    fig, ax = _fig_ax(ax)
    for k, (name, r) in enumerate(results.items()):
        s = np.maximum(r.identifiability.singular_values, 1e-16)
        ax.semilogy(np.arange(1, s.size + 1), s, "o-", ms=3, color=f"C{k}",
                    label=f"{name}: {r.n_retained} retained")
        if np.isfinite(r.identifiability.sigma_bar):
            ax.axhline(1 / r.identifiability.sigma_bar, color=f"C{k}", ls="--", lw=0.8)
    ax.set_xlabel("index i")
    ax.set_ylabel("s_i [1/scale]")
    ax.set_title("singular-value spectra by sensor set (dashed: each cut 1/σ̄)", fontsize=10, y=1.0)
    lean_log_ticks(ax)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, own)


def plot_truncation(result: CalibrationResult, ax=None):
    """Cross-validation criterion against the number of retained θ, with the choice.

    Returns
    -------
    matplotlib.figure.Figure or None
        None for an explicit σ̄ (no truncation curve).
    """
    t = result.identifiability.truncation
    if not t:
        return None
    own = ax is None
    fig, ax = _fig_ax(ax)
    k, cv, fit = np.asarray(t["n_retained"]), np.asarray(t["cv"], float), np.asarray(t["fit"], float)
    finite = np.isfinite(cv)
    ax.semilogy(k[finite], cv[finite], "o-", ms=3, color="C0",
                label=f"{t.get('criterion', 'K-fold')} cross-validated error (criterion)")
    ax.semilogy(k, np.maximum(fit, 1e-12), "s-", ms=2, color="0.5", lw=0.8, label="in-sample fit")
    chosen = int(t["chosen"])
    ax.axvline(chosen, color="C3", ls="--", lw=1, label=f"chosen: {chosen} retained")
    if t.get("prior_limit") is not None and int(t["prior_limit"]) < int(k[-1]):
        ax.axvspan(int(t["prior_limit"]) + 0.5, int(k[-1]) + 0.5, color="0.85", zorder=0,
                   label="data determine θ worse than the prior (not chosen)")
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xlabel("number of retained θ")
    ax.set_ylabel("mean squared whitened error [-]")
    ax.set_title(f"{result.name}: truncation chosen by the data", fontsize=10, y=1.0)
    lean_log_ticks(ax)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _finish(fig, own)
