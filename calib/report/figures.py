"""Figures of a calibration (matplotlib, Agg backend; PNG and SVG).

- singular-value spectrum with the cut s = 1/σ̄,
- the truncation criterion against the number retained (automatic truncation),
- eigenshape maps ψ_i(α, η) of the retained parameters, lift and drag blocks separately,
  with the (α, η) points the data see,
- Cramér–Rao correlation matrix,
- measured vs model before/after for each channel against tip-speed ratio,
- corrected polars with confidence bands.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from calib.result import CalibrationResult  # noqa: E402

FORMATS = ("png", "svg")


def plot_singular_values(result: CalibrationResult, ax=None):
    """Singular values s_i of the whitened scaled sensitivities with the cut 1/σ̄."""
    fig, ax = _fig_ax(ax, (6.4, 3.6))
    s = result.singular_values
    i = np.arange(1, s.size + 1)
    keep = result.retained
    ax.semilogy(i[keep], np.maximum(s[keep], 1e-16), "o", color="C0", label=f"retained ({keep.sum()})")
    ax.semilogy(i[~keep], np.maximum(s[~keep], 1e-16), "x", color="C3", label=f"frozen ({(~keep).sum()})")
    if np.isfinite(result.sigma_bar):
        ax.axhline(1.0 / result.sigma_bar, color="k", ls="--", lw=1,
                   label=f"cut 1/σ̄ = {1 / result.sigma_bar:.3g}")
    ax.set_xlabel("index i")
    ax.set_ylabel("singular value s_i = 1/σ(θ_i) [1/scale]")
    ax.set_title(f"{result.name}: singular-value spectrum")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def plot_spectra(results: Mapping[str, CalibrationResult], ax=None):
    """Singular-value spectra of several calibrations (e.g. sensor sets) on one axis."""
    fig, ax = _fig_ax(ax, (6.4, 3.6))
    for k, (name, r) in enumerate(results.items()):
        s = np.maximum(r.singular_values, 1e-16)
        ax.semilogy(np.arange(1, s.size + 1), s, "o-", ms=3, color=f"C{k}",
                    label=f"{name}: {r.n_retained} retained")
        if np.isfinite(r.sigma_bar):
            ax.axhline(1 / r.sigma_bar, color=f"C{k}", ls="--", lw=0.8)
    ax.set_xlabel("index i")
    ax.set_ylabel("s_i [1/scale]")
    ax.set_title("singular-value spectra by sensor set")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _eigen_mesh(result: CalibrationResult, n_alpha: int = 121, n_eta: int = 61):
    grid = result.layout.grid
    a, e = grid.alpha_nodes_deg, grid.eta_nodes
    return np.linspace(a[0], a[-1], n_alpha), np.linspace(e[0], e[-1], n_eta)


def plot_eigenshapes(result: CalibrationResult, block: str = "lift", max_modes: int = 12):
    """Eigenshape maps ψ_i(α, η) of the retained θ for one block ("lift" or "drag")."""
    if not result.layout.has_field:
        return None
    modes = np.flatnonzero(result.retained)[:max_modes]
    alpha, eta = _eigen_mesh(result)
    n = max(len(modes), 1)
    ncol = min(4, n)
    nrow = int(np.ceil(n / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.2 * ncol, 2.6 * nrow), squeeze=False,
                             constrained_layout=True)
    if len(modes):
        lift, drag = result.eigenshapes(alpha, eta, modes)
        shapes = lift if block == "lift" else drag
        vmax = max(float(np.abs(shapes).max()), 1e-12)
    for k, ax in enumerate(axes.flat):
        if k >= len(modes):
            ax.axis("off")
            continue
        im = ax.pcolormesh(alpha, eta, shapes[k], cmap="RdBu_r", vmin=-vmax, vmax=vmax, shading="auto",
                           rasterized=True)
        if result.alpha_seen.size:
            ax.plot(result.alpha_seen, result.eta_seen, ".", ms=1, color="k", alpha=0.25, rasterized=True)
        i = modes[k]
        ax.set_title(f"θ{i + 1}  σ={result.sigma_theta[i]:.2g}", fontsize=9)
        ax.set_xlabel("α [deg]", fontsize=8)
        ax.set_ylabel("η = r/R [-]", fontsize=8)
        ax.tick_params(labelsize=7)
    if not len(modes):
        axes.flat[0].text(0.5, 0.5, "no retained parameter", ha="center", va="center")
    else:
        fig.colorbar(im, ax=axes, shrink=0.8, label=f"ψ ({block}) [scale units per unit θ]")
    fig.suptitle(f"{result.name}: {block} eigenshapes (dots: (α, η) seen by the data)", fontsize=10)
    return fig


def plot_correlation(result: CalibrationResult, ax=None):
    """Cramér–Rao correlation matrix of the full parameter vector (NaN: unobservable)."""
    n = result.n_params
    fig, ax = _fig_ax(ax, (6.0, 5.2))
    c = np.ma.masked_invalid(result.correlation)
    im = ax.imshow(c, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest")
    fig.colorbar(im, ax=ax, label="correlation χ_pq [-]")
    if n <= 40:
        names = [d["name"] for d in result.parameters]
        ax.set_xticks(range(n), names, rotation=90, fontsize=5)
        ax.set_yticks(range(n), names, fontsize=5)
    ax.set_title(f"{result.name}: Cramér–Rao correlations (blank: unobservable)", fontsize=9)
    return fig


def plot_fit(result: CalibrationResult):
    """Measured vs model before and after calibration, one panel per channel, against λ."""
    x = result.tip_speed_ratio()
    xlabel = "tip-speed ratio λ [-]"
    if x is None:
        x, xlabel = result.conditions["wind_speed"], "wind speed [m/s]"
    nc = len(result.channels)
    ncol = min(3, nc)
    nrow = int(np.ceil(nc / ncol))
    fig, axes = plt.subplots(nrow, ncol, figsize=(4.2 * ncol, 3.2 * nrow), squeeze=False,
                             constrained_layout=True)
    pitch = result.conditions["pitch"]
    for k, ax in enumerate(axes.flat):
        if k >= nc:
            ax.axis("off")
            continue
        ch, unit = result.channels[k], result.channel_units[k]
        order = np.lexsort((x, pitch))
        ax.errorbar(x[order], result.measured[order, k], yerr=result.sigma[order, k], fmt=".", color="k",
                    ms=3, lw=0.6, label="measured")
        okb, oka = result.status_before == 0, result.status_after == 0
        ax.plot(x[okb], result.model_before[okb, k], "x", color="C3", ms=4, label="model before")
        ax.plot(x[oka], result.model_after[oka, k], "o", mfc="none", color="C0", ms=4, label="model after")
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel(f"{ch} [{unit}]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7)
    fig.suptitle(f"{result.name}: measured vs model", fontsize=10)
    return fig


def plot_polars(result: CalibrationResult, max_stations: int = 5):
    """Corrected polars C = C₀ + ΔC with confidence bands, lift (top) and drag (bottom)."""
    pb = result.polar_bands
    if not pb:
        return None
    alpha, eta = np.asarray(pb["alpha_deg"]), np.asarray(pb["eta"])
    idx = np.unique(np.linspace(0, eta.size - 1, min(max_stations, eta.size)).round().astype(int))
    fig, axes = plt.subplots(2, idx.size, figsize=(3.2 * idx.size, 5.4), squeeze=False, constrained_layout=True)
    conf = float(pb.get("confidence", 0.95))
    for col, j in enumerate(idx):
        for row, letter in enumerate(("cl", "cd")):
            ax = axes[row, col]
            base = np.asarray(pb[f"{letter}0"])[j] if f"{letter}0" in pb else np.zeros_like(alpha)
            d, hw = np.asarray(pb[f"d{letter}"])[j], np.asarray(pb[f"d{letter}_half_width"])[j]
            ax.plot(alpha, base, color="0.5", lw=1, label="nominal")
            ax.plot(alpha, base + d, color="C0", lw=1.2, label="calibrated")
            ax.fill_between(alpha, base + d - hw, base + d + hw, color="C0", alpha=0.25,
                            label=f"{100 * conf:.0f}% band")
            frac_key = f"d{letter}_prior_fraction"
            if frac_key in pb:
                prior_dom = np.asarray(pb[frac_key])[j] > 0.5
                if prior_dom.any():
                    ax.fill_between(alpha, base + d - hw, base + d + hw, where=prior_dom, color="C1",
                                    alpha=0.25, label="band set by the prior (data say little)")
            if result.alpha_seen.size:
                near = np.abs(result.eta_seen - eta[j]) <= 0.5 * _spacing(eta, j)
                if near.any():
                    ax.axvspan(result.alpha_seen[near].min(), result.alpha_seen[near].max(), color="C2",
                               alpha=0.08, label="α seen")
            ax.set_title(f"η = {eta[j]:.2f}", fontsize=9)
            ax.set_xlabel("α [deg]", fontsize=8)
            ax.set_ylabel("C_L [-]" if letter == "cl" else "C_D [-]", fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(True, alpha=0.3)
            if col == 0 and row == 0:
                ax.legend(fontsize=7)
    fig.suptitle(f"{result.name}: corrected polars" + ("" if "cl0" in pb else " (corrections only)"),
                 fontsize=10)
    return fig


def plot_truncation(result: CalibrationResult, ax=None):
    """Leave-one-point-out criterion against the number of retained θ, with the choice."""
    t = result.truncation
    if not t:
        return None
    fig, ax = _fig_ax(ax, (6.4, 3.6))
    k, cv, fit = np.asarray(t["n_retained"]), np.asarray(t["cv"], float), np.asarray(t["fit"], float)
    finite = np.isfinite(cv)
    ax.semilogy(k[finite], cv[finite], "o-", ms=3, color="C0", label="leave-one-point-out error (criterion)")
    ax.semilogy(k, np.maximum(fit, 1e-12), "s-", ms=2, color="0.5", lw=0.8, label="in-sample fit")
    chosen = int(t["chosen"])
    ax.axvline(chosen, color="C3", ls="--", lw=1, label=f"chosen: {chosen} retained")
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.set_xlabel("number of retained θ")
    ax.set_ylabel("mean squared whitened error [-]")
    ax.set_title(f"{result.name}: truncation chosen by the data")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _spacing(eta, j):
    if eta.size < 2:
        return 1.0
    return float(np.min(np.abs(np.diff(eta)))) if eta.size > 1 else 1.0


def _fig_ax(ax, size):
    if ax is None:
        fig, ax = plt.subplots(figsize=size, constrained_layout=True)
        return fig, ax
    return ax.figure, ax


FIGURES = {
    "singular_values": plot_singular_values,
    "truncation": plot_truncation,
    "eigenshapes_lift": lambda r: plot_eigenshapes(r, "lift"),
    "eigenshapes_drag": lambda r: plot_eigenshapes(r, "drag"),
    "correlation": plot_correlation,
    "fit": plot_fit,
    "polars": plot_polars,
}


def save_figure(fig, out_dir: str | Path, stem: str, formats=FORMATS) -> dict[str, Path]:
    """Save ``fig`` as ``out_dir/stem.<fmt>`` for each format; closes the figure."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {}
    for fmt in formats:
        path = out_dir / f"{stem}.{fmt}"
        fig.savefig(path, dpi=110)
        paths[fmt] = path
    plt.close(fig)
    return paths


def write_figures(result: CalibrationResult, out_dir: str | Path, prefix: str = "",
                  formats=FORMATS) -> dict[str, dict[str, Path]]:
    """Write every figure of ``result``; returns name -> {format: path}."""
    out = {}
    for name, make in FIGURES.items():
        fig = make(result)
        if fig is not None:
            out[name] = save_figure(fig, out_dir, f"{prefix}{name}", formats)
    return out
