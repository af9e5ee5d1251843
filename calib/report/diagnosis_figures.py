"""The figures of a diagnosis report (:mod:`calib.report.diagnosis_report`).

- ``gap.png``: whitened residuals of each channel against tip-speed ratio, nominal / with the
  named effect(s) / after the recalibration;
- ``candidates.png``: ΔBIC of every candidate of the first round, the named one marked.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FixedLocator, NullLocator

from calib.report.figures import save_figure
from calib.report.panels import (DPI, Margins, lean_ticks, panel_grid, plain_numbers, settle_labels, single_panel,
                                 title_height, wrap_title)
from calib.words import p_is

GAP_PANEL = (3.6, 2.2)        # one channel's panel [in]
GAP_COLUMNS = 3               # panels across: three fit a report's width at a readable size
#: Kass & Raftery (1995), on 2 ln B ≈ ΔBIC: evidence against a candidate relative to the best
#: is "positive" above 2, "strong" above 6, "very strong" above 10.
EVIDENCE_LEVELS = (2.0, 6.0, 10.0)


def plot_gap(d) -> Figure:
    """Whitened residuals (measured − model)/σ per channel against tip-speed ratio: nominal,
    with the named effect(s), after the recalibration; at most three panels across.

    "With the effect" is a hollow circle and "after recalibration" a dot drawn inside it, so
    that both stay visible where the recalibration changes nothing.
    """
    lam = np.asarray(d.find["tip_speed_ratio"], float)
    n = len(d.channels)
    ncol = min(GAP_COLUMNS, max(n, 1))
    nrow = int(np.ceil(max(n, 1) / ncol))
    margins = Margins(left=0.85, right=0.25, bottom=0.6, wgap=0.85, hgap=0.75)
    width = margins.left + ncol * GAP_PANEL[0] + (ncol - 1) * margins.wgap + margins.right
    title = wrap_title("Where the gap is: whitened residuals (measured − model)/σ against tip-speed ratio; "
                       "grey band ±2", width, 9)
    top = title_height(title, 9) + 0.35                      # the title and a legend row under it
    fig, axes = panel_grid(nrow, ncol, GAP_PANEL, replace(margins, top=top), n_panels=n)
    series = [("nominal", d.model_before, dict(marker="x", color="C3", ms=5)),
              (f"with {', '.join(d.effects) or 'no effect'}", d.model_with_effects,
               dict(marker="o", mfc="none", color="C0", ms=7, mew=1.0))]
    if d.model_after is not None:
        series.append(("after recalibration", d.model_after, dict(marker=".", color="C2", ms=5)))
    for j, c in enumerate(d.channels):
        ax = axes[j // ncol, j % ncol]
        for label, model, style in series:
            w = (np.asarray(d.measured)[:, j] - np.asarray(model)[:, j]) / np.asarray(d.sigma)[:, j]
            ax.plot(lam, w, ls="none", label=label, **style)
        ax.axhspan(-2, 2, color="0.9", zorder=0)
        ax.axhline(0, color="k", lw=0.6)
        lean_ticks(ax)
        plain_numbers(ax)
        ax.tick_params(labelsize=7)
        ax.set_title(c, fontsize=8, pad=3)
        ax.set_xlabel("tip-speed ratio λ [-]", fontsize=8)
        if j % ncol == 0:
            ax.set_ylabel("(meas. − model)/σ [-]", fontsize=8)
        ax.grid(True, alpha=0.3)
    if n:
        handles = [Line2D([], [], ls="none", **style) for _, _, style in series]
        fig.legend(handles, [label for label, _, _ in series], loc="upper center", ncol=len(series), fontsize=8,
                   frameon=False, bbox_to_anchor=(0.5, 1 - (title_height(title, 9) - 0.05) / fig.get_figheight()))
    fig.suptitle(title, fontsize=9, y=1 - 0.06 / fig.get_figheight())
    settle_labels(fig)
    return fig


def plot_candidates(d) -> Figure:
    """ΔBIC of every candidate of the first round to the best one, on a scale linear to 2 and
    logarithmic beyond; the named candidate in blue, the evidence levels of Kass & Raftery
    (1995) dotted, and each candidate's likelihood-ratio p-value and BIC weight beside it.

    References
    ----------
    R.E. Kass, A.E. Raftery, Bayes factors, J. Am. Stat. Assoc. 90 (1995) 773-795.
    """
    fits = d.candidates
    names = [f.name for f in fits]
    label_width = 0.75 + 0.065 * max((len(s) for s in names), default=10)      # 8 pt names [in]
    height = 0.32 * max(len(fits), 3) + 1.5
    fig, ax = single_panel((10.0, height), Margins(left=label_width, right=1.9, bottom=0.55, top=0.75))
    if not fits:
        ax.text(0.5, 0.5, "no candidates", ha="center", transform=ax.transAxes)
        return fig
    dbic = np.array([f.bic for f in fits]) - min(f.bic for f in fits)
    named = d.rounds[0]["verdict"] if d.rounds else ""
    first = next((f for f in fits if f.effect == named), None)
    colors = ["C0" if f is first else ("0.35" if f.significant else "0.7") for f in fits]
    y = np.arange(len(fits))
    ax.hlines(y, 0, dbic, colors=colors, lw=2)
    ax.scatter(dbic, y, c=colors, s=28, zorder=3)
    for k, f in enumerate(fits):
        ax.text(1.02, k, f"{p_is(f.p_value)}, weight {f.weight:.2f}", transform=ax.get_yaxis_transform(),
                va="center", fontsize=7)
    ax.set_yticks(y, names, fontsize=8)
    ax.set_ylim(len(fits) - 0.5, -0.5)
    ax.set_xscale("symlog", linthresh=2.0, linscale=0.5)
    right = max(30.0, 3.0 * float(dbic.max()))
    ax.set_xlim(0, right)
    ticks = [t for t in (0, 2, 6, 10, 30, 100, 300, 1e3, 3e3, 1e4, 3e4, 1e5, 3e5, 1e6) if t <= right]
    ax.xaxis.set_major_locator(FixedLocator(ticks))
    ax.xaxis.set_minor_locator(NullLocator())
    ax.set_xticklabels([f"{t:g}" for t in ticks], fontsize=7)
    for level in EVIDENCE_LEVELS:
        ax.axvline(level, color="0.5", lw=0.7, ls=":")
    ax.set_xlabel("ΔBIC to the best candidate [-] (dotted: 2, 6, 10 = positive, strong, very strong evidence "
                  "against; linear below 2)", fontsize=8)
    ax.grid(True, axis="x", alpha=0.3)
    handles = [Line2D([], [], marker="o", ls="none", color=c) for c in ("C0", "0.35", "0.7")]
    ax.legend(handles, ["named", "significant by likelihood ratio", "not significant"], fontsize=7, ncol=3,
              loc="lower right", bbox_to_anchor=(1.0, 1.0), frameon=False, handletextpad=0.2)
    fig.text(0.01, 1 - 0.12 / height, f"Candidates of the first round; named: {d.effect}", fontsize=9, va="top")
    return fig


def write_figures(d, out: Path, say) -> dict[str, Path]:
    """Write ``gap.png`` and ``candidates.png`` into ``out`` (atomically), telling ``say`` each name."""
    figs = {}
    for name, make in (("gap", plot_gap), ("candidates", plot_candidates)):
        say(f"figure {name}")
        figs[name] = save_figure(make(d), out, name, ("png",), dpi=DPI)["png"]
    return figs
