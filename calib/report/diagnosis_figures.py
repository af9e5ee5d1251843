"""The figures of a diagnosis report (:mod:`calib.report.diagnosis_report`).

- ``gap.png``: whitened residuals of each channel against tip-speed ratio, nominal / with the
  named effect(s) / after the recalibration;
- ``candidates.png``: ΔBIC of every candidate of the first round, the named one marked.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from calib.report.atomic import atomic_path  # noqa: E402
from calib.words import p_is  # noqa: E402


def plot_gap(d) -> plt.Figure:
    """Whitened residuals per channel against tip-speed ratio: nominal, with effects, after."""
    lam = np.asarray(d.find["tip_speed_ratio"])
    n = len(d.channels)
    fig, axes = plt.subplots(1, n, figsize=(4.2 * n, 3.6), squeeze=False)
    series = [("nominal", d.model_before, "C3", "x"),
              (f"with {', '.join(d.effects) or 'no effect'}", d.model_with_effects, "C0", "o")]
    if d.model_after is not None:
        series.append(("after recalibration", d.model_after, "C2", "."))
    for j, c in enumerate(d.channels):
        ax = axes[0, j]
        for label, model, color, marker in series:
            w = (d.measured[:, j] - model[:, j]) / d.sigma[:, j]
            ax.plot(lam, w, marker, color=color, ms=4, ls="none", label=label)
        ax.axhspan(-2, 2, color="0.9", zorder=0)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("tip-speed ratio λ [-]")
        ax.set_ylabel("(measured − model)/σ [-]")
        ax.set_title(c, fontsize=10)
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.suptitle("Where the gap is: whitened residuals (grey band ±2σ)", fontsize=10)
    fig.tight_layout()
    return fig


def plot_candidates(d) -> plt.Figure:
    """ΔBIC of every candidate against the model without it (first round), named one marked."""
    fits = d.candidates
    fig, ax = plt.subplots(figsize=(9.5, 0.45 * max(len(fits), 3) + 1.4))
    if not fits:
        ax.text(0.5, 0.5, "no candidates", ha="center")
        return fig
    base = min(f.bic for f in fits)
    names = [f.name for f in fits]
    dbic = np.array([f.bic - base for f in fits])
    named = d.rounds[0]["verdict"] if d.rounds else ""
    colors = ["C0" if (f.effect == named and f is fits[0]) else ("0.6" if f.significant else "0.85") for f in fits]
    ax.barh(range(len(fits)), dbic + 0.5, color=colors)
    for k, f in enumerate(fits):
        ax.text(dbic[k] + 0.6, k, f"{p_is(f.p_value)}, weight {f.weight:.2f}", va="center", fontsize=7)
    ax.set_yticks(range(len(fits)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("symlog", linthresh=10)
    ax.set_xlabel("ΔBIC to the best candidate (+0.5) [-]")
    ax.set_title(f"Named: {d.effect}\n(blue: named; grey: significant by likelihood ratio; light: not)", fontsize=9)
    ax.set_xlim(0, max(float(dbic.max()) * 8, 100))
    ax.grid(True, axis="x", alpha=0.3)
    fig.tight_layout()
    return fig


def write_figures(d, out: Path, say) -> dict[str, Path]:
    """Write ``gap.png`` and ``candidates.png`` into ``out`` (atomically), telling ``say`` each name."""
    figs = {}
    for name, make in (("gap", plot_gap), ("candidates", plot_candidates)):
        say(f"figure {name}")
        fig = make(d)
        with atomic_path(out / f"{name}.png") as tmp:
            fig.savefig(tmp, dpi=100, format="png")
        figs[name] = out / f"{name}.png"
        plt.close(fig)
    return figs
