"""Figures of a campaign design: the chosen points on the λ–pitch plane over the candidate grid, and
the marginal-gain curve. Plain matplotlib ``Figure`` objects (no pyplot state), report width."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

__all__ = ["design_figure", "gain_figure"]


def design_figure(res) -> Figure:
    """The candidates (grey), failed candidates (x), the space-filling design of the same size
    (open squares), the fixed points and the chosen points (numbered in run order) on the λ–pitch plane."""
    pr = res.problem
    lam = res.candidates.tip_speed_ratio(pr.envelope.radius)
    pitch = res.candidates.pitch
    fig = Figure(figsize=(7.5, 4.8))
    ax = fig.add_subplot()
    ax.plot(lam[res.ok], pitch[res.ok], ".", color="0.75", ms=3, label=f"candidates ({int(res.ok.sum())})")
    if res.n_failed:
        ax.plot(lam[~res.ok], pitch[~res.ok], "x", color="C3", ms=4, label=f"model failed ({res.n_failed})")
    ax.plot(lam[res.uniform], pitch[res.uniform], "s", mfc="none", mec="C2", ms=7,
            label=f"space-filling design ({len(res.uniform)})")
    order = res.run_order()
    idx, counts = np.unique(res.design, return_counts=True)
    mult = dict(zip(idx.tolist(), counts.tolist()))
    free = [j for j in idx if j not in set(res.fixed.tolist())]
    ax.plot(lam[free], pitch[free], "o", color="C0", ms=7, label=f"design ({len(res.design)} runs)")
    if res.fixed.size:
        ax.plot(lam[res.fixed], pitch[res.fixed], "D", color="C1", ms=7, label=f"fixed ({res.fixed.size})")
    for k, j in enumerate(order):
        ax.annotate(f"{k + 1}" + (f"×{mult[j]}" if mult[j] > 1 else ""), (lam[j], pitch[j]), fontsize=6.5,
                    xytext=(3, 3), textcoords="offset points")
    ax.set_xlabel("tip-speed ratio λ [-]")
    ax.set_ylabel("pitch [deg]")
    ax.set_title(f"{res.criterion}: {len(res.design)} points (numbers: run order)", fontsize=10)
    ax.grid(alpha=0.3)
    fig.legend(*ax.get_legend_handles_labels(), fontsize=7.5, loc="lower center", ncol=4, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return fig


def gain_figure(res) -> Figure:
    """The criterion's gain of each greedy point, and the cumulative share of the full set's log det."""
    g = res.selection.greedy_gains
    n0 = res.fixed.size
    k = np.arange(n0 + 1, n0 + g.size + 1)
    fig = Figure(figsize=(7.5, 3.8))
    ax = fig.add_subplot()
    ax.plot(k, g, "o-", color="C0", ms=3, label="gain of the point added")
    ax.axvline(len(res.design), color="k", lw=0.8, ls="--", label=f"budget {len(res.design)}")
    ax.set_xlabel("points in the design")
    ax.set_ylabel("criterion gain [-]")
    ax.grid(alpha=0.3)
    curve = res.logdet_curve
    if curve.size and np.isfinite(res.logdet.get("full", np.nan)) and res.logdet["full"] > 0:
        ax2 = ax.twinx()
        ax2.plot(k[:curve.size], 100 * curve / res.logdet["full"], "-", color="C1",
                 label="log det of the parameters, % of the full candidate set")
        ax2.set_ylabel("% of the full set's log det")
        ax2.legend(fontsize=7.5, loc="center right")
    ax.legend(fontsize=7.5, loc="upper right")
    ax.set_title("Marginal gain of each added point (greedy order)", fontsize=10)
    fig.tight_layout()
    return fig
