"""Corrected polars C = C₀ + ΔC(α, η) with confidence bands at a few span stations.

Lift on top, drag below (one scale per row), one column per η station, on the α range of
the correction nodes (the corrections are defined there; the α the data reach at each
station is stated in the panel title and shaded where it overlaps the node range). Where more than half of a band's
variance comes from the prior (the data say little) the band is shaded in another colour.
For a synthetic run a known truth ΔC(α, η) can be overlaid.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from calib.report.panels import Margins, lean_ticks, panel_grid, settle_labels, title_height, wrap_title
from calib.result import CalibrationResult

TruthField = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def station_columns(eta: np.ndarray, max_stations: int) -> np.ndarray:
    """Indices of at most ``max_stations`` η stations spread over ``eta``."""
    return np.unique(np.linspace(0, eta.size - 1, min(max_stations, eta.size)).round().astype(int))


def _seen_near(result: CalibrationResult, eta: np.ndarray, j: int) -> np.ndarray:
    """α [deg] seen by the data within half a station spacing of ``eta[j]``."""
    if not result.alpha_seen.size:
        return np.zeros(0)
    half = 0.5 * float(np.min(np.diff(eta))) if eta.size > 1 else 1.0
    return result.alpha_seen[np.abs(result.eta_seen - eta[j]) <= half]


def plot_polars(result: CalibrationResult, max_stations: int = 5, truth: TruthField | None = None):
    """Corrected polars with confidence bands, lift (top) and drag (bottom).

    Parameters
    ----------
    result : CalibrationResult
    max_stations : int
        Number of η stations drawn (spread over the band stations).
    truth : callable, optional
        ``truth(alpha_deg, eta) -> (dcl, dcd)``, the known true corrections of a synthetic
        run (arrays broadcast like the inputs) [-]; drawn dashed as C₀ + ΔC_true.

    Returns
    -------
    matplotlib.figure.Figure or None
        None when the result has no polar bands.
    """
    pb = result.polar_bands
    if not pb:
        return None
    alpha, eta = np.asarray(pb["alpha_deg"], float), np.asarray(pb["eta"], float)
    idx = station_columns(eta, max_stations)
    margins = Margins(left=0.75, right=0.2, bottom=0.55, top=0.75, wgap=0.15, hgap=0.55)
    size = (2.6, 2.1)
    what = "corrected polars" + ("" if "cl0" in pb else " (corrections only)")
    width = margins.left + idx.size * size[0] + (idx.size - 1) * margins.wgap + margins.right
    title = wrap_title(f"{result.name}: {what} on the α range of the correction nodes ({alpha[0]:g}…{alpha[-1]:g}°)"
                       + ("; dashed: known truth" if truth is not None else ""), width, 9)
    fig, axes = panel_grid(2, idx.size, size, replace(margins, top=title_height(title, 9) + 0.3))
    fig.suptitle(title, fontsize=9, y=1 - 0.08 / fig.get_size_inches()[1])
    conf = float(pb.get("confidence", 0.95))
    truth_d = None
    if truth is not None:
        A, E = np.meshgrid(alpha, eta[idx])
        truth_d = [np.broadcast_to(np.asarray(t, float), A.shape) for t in truth(A, E)]
    for col, j in enumerate(idx):
        seen = _seen_near(result, eta, j)
        for row, letter in enumerate(("cl", "cd")):
            ax = axes[row, col]
            base = np.asarray(pb[f"{letter}0"])[j] if f"{letter}0" in pb else np.zeros_like(alpha)
            d, hw = np.asarray(pb[f"d{letter}"])[j], np.asarray(pb[f"d{letter}_half_width"])[j]
            ax.plot(alpha, base, color="0.5", lw=1, label="nominal")
            ax.fill_between(alpha, base + d - hw, base + d + hw, color="C0", alpha=0.25, lw=0,
                            label=f"{100 * conf:.0f}% band")
            frac_key = f"d{letter}_prior_fraction"
            if frac_key in pb:
                prior_dom = np.asarray(pb[frac_key])[j] > 0.5
                if prior_dom.any():
                    ax.fill_between(alpha, base + d - hw, base + d + hw, where=prior_dom, color="C1", alpha=0.25,
                                    lw=0, label="band set by the prior (data say little)")
            ax.plot(alpha, base + d, color="C0", lw=1.2, label="calibrated")
            if truth_d is not None:
                ax.plot(alpha, base + truth_d[row][col], "--", color="k", lw=1, label="truth")
            if seen.size:
                lo, hi = max(seen.min(), alpha[0]), min(seen.max(), alpha[-1])
                if lo < hi:
                    ax.axvspan(lo, hi, color="C2", alpha=0.08, lw=0, label="α seen")
            ax.set_xlim(alpha[0], alpha[-1])
            lean_ticks(ax)
            if col == 0:
                ax.set_ylabel("C_L [-]" if letter == "cl" else "C_D [-]", fontsize=8)
            ax.tick_params(labelsize=7, labelleft=col == 0, labelbottom=row == 1)
            ax.grid(True, alpha=0.3)
            if row == 0:
                ax.set_title(f"η = {eta[j]:.2f}" + (f"; α seen {seen.min():.0f}…{seen.max():.0f}°" if seen.size
                                                     else "; no α seen"), fontsize=8, pad=3, y=1.0)
            else:
                ax.set_xlabel("α [deg]", fontsize=8)
            if col == 0 and row == 0:
                ax.legend(fontsize=6, loc="best")
    for row in axes:                                     # one C_L and one C_D scale across the stations
        lo = min(ax.dataLim.y0 for ax in row)
        hi = max(ax.dataLim.y1 for ax in row)
        pad = 0.05 * (hi - lo) if hi > lo else 0.05
        for ax in row:
            ax.set_ylim(lo - pad, hi + pad)
    settle_labels(fig)
    return fig
