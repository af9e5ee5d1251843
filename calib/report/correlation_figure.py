"""The Cramér–Rao correlation matrix, its axes labelled by parameter.

A 61 × 61 matrix cannot carry 61 readable names per axis. Correction nodes are therefore
shown in a fixed order (lift block, then drag block; α nodes ascending; within each α node
the η nodes ascending) and labelled once per α node (``ΔC_L α=8°``), with the η order stated
in the title; every other parameter (pitch offset, wind-speed scale, ...) is labelled by
name. Thin lines separate the blocks and the α groups.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.result import CalibrationResult
from calib.report.panels import Margins, colorbar_axes, panel_grid, settle_labels, spread

BLOCK_LABEL = {"lift": "ΔC_L", "drag": "ΔC_D"}
MATRIX_SIZE = 5.6          # side of the matrix [in]
LABEL_SIZE = 7             # of the group labels [pt]
LEADER = 0.12              # length of the leader from a group to its label, where labels were moved apart [in]


@dataclass(frozen=True)
class ParameterGroup:
    """Consecutive rows of the displayed matrix that share one label.

    Attributes
    ----------
    label : str
    start, stop : int
        Displayed rows ``start:stop``.
    block : str
        ``"lift"``, ``"drag"`` or ``"other"``.
    """

    label: str
    start: int
    stop: int
    block: str


def display_order(result: CalibrationResult) -> tuple[np.ndarray, list[ParameterGroup]]:
    """Order of the parameters in the correlation figure and the labelled groups.

    Parameters
    ----------
    result : CalibrationResult

    Returns
    -------
    order : ndarray of int, shape (n_params,)
        Parameter index of each displayed row.
    groups : list of ParameterGroup
        One per (block, α node) of the correction field, one per other parameter.
    """
    order, groups = [], []
    lay = result.layout
    if lay.has_field:
        for block, index in (("lift", lay.lift_index), ("drag", lay.drag_index)):
            for a, alpha in enumerate(lay.grid.alpha_nodes_deg):
                idx = [int(i) for i in index[a] if i >= 0]
                if idx:
                    groups.append(ParameterGroup(f"{BLOCK_LABEL[block]} α={alpha:g}°", len(order),
                                                 len(order) + len(idx), block))
                    order += idx
    placed = set(order)
    for i, p in enumerate(result.parameters):
        if i not in placed:
            groups.append(ParameterGroup(str(p["name"]), len(order), len(order) + 1, "other"))
            order.append(i)
    return np.asarray(order, int), groups


def plot_correlation(result: CalibrationResult):
    """Cramér–Rao correlation matrix of the full parameter vector (blank: unobservable).

    Returns
    -------
    matplotlib.figure.Figure
    """
    order, groups = display_order(result)
    n = order.size
    fig, axes = panel_grid(1, 1, (MATRIX_SIZE, MATRIX_SIZE), Margins(left=1.5, right=1.1, bottom=1.5, top=0.75))
    ax = axes[0, 0]
    c = np.ma.masked_invalid(np.asarray(result.identifiability.correlation)[np.ix_(order, order)])
    im = ax.imshow(c, cmap="RdBu_r", vmin=-1, vmax=1, interpolation="nearest", extent=(-0.5, n - 0.5, n - 0.5, -0.5))
    _label_groups(ax, groups, n)
    ax.set_xlim(-0.5, n - 0.5)
    ax.set_ylim(n - 0.5, -0.5)
    bounds = [g.start - 0.5 for g in groups[1:]]
    major = [g.start - 0.5 for k, g in enumerate(groups[1:]) if g.block != groups[k].block]
    minor = [b for b in bounds if b not in major]
    for lines, lw, color in ((minor, 0.3, "0.75"), (major, 1.0, "k")):
        if lines:
            ax.vlines(lines, -0.5, n - 0.5, colors=color, lw=lw)
            ax.hlines(lines, -0.5, n - 0.5, colors=color, lw=lw)
    cax = colorbar_axes(fig, axes)
    fig.colorbar(im, cax=cax)
    cax.set_ylabel("correlation χ_pq [-]", fontsize=8)
    cax.tick_params(labelsize=7)
    title = f"{result.name}: Cramér–Rao correlations of the {n} parameters (blank: unobservable)"
    lay = result.layout
    if lay.has_field:
        etas = ", ".join(f"{e:g}" for e in lay.grid.eta_nodes)
        title += f"\ncorrection nodes grouped by α node; inside each group η = {etas}"
    ax.set_title(title, fontsize=8, y=1.0)
    settle_labels(fig)
    return fig


def _label_groups(ax, groups: list[ParameterGroup], n: int) -> None:
    """Label each group of rows (and columns) at its centre, or, where rows are too thin for
    neighbouring labels (two single parameters after the field), moved apart just enough with a
    leader line from the group to its label.

    Parameters
    ----------
    ax : Axes
        The matrix, rows and columns ``-0.5 … n - 0.5`` [rows].
    groups : list of ParameterGroup
    n : int
        Rows of the matrix.
    """
    centers = np.array([0.5 * (g.start + g.stop - 1) for g in groups])
    labels = [g.label for g in groups]
    gap = 1.25 * LABEL_SIZE / 72.0 * n / MATRIX_SIZE           # one line of label text [rows]
    placed = spread(centers, gap, -0.5 + 0.4 * gap, n - 0.5 - 0.4 * gap)
    moved = np.abs(placed - centers) > 0.05
    lead = LEADER * 72.0 if moved.any() else 0.0               # [pt]
    ax.set_xticks(placed, labels, rotation=90, fontsize=LABEL_SIZE)
    ax.set_yticks(placed, labels, fontsize=LABEL_SIZE)
    ax.tick_params(length=0, pad=3.5 + lead)
    length = LEADER * n / MATRIX_SIZE                          # [rows]
    for k in np.flatnonzero(moved):     # left edge x = -0.5; bottom edge y = n - 0.5 (the y axis points down)
        ax.plot([-0.5, -0.5 - length], [centers[k], placed[k]], color="0.4", lw=0.6, clip_on=False)
        ax.plot([centers[k], placed[k]], [n - 0.5, n - 0.5 + length], color="0.4", lw=0.6, clip_on=False)
