"""Eigenshape maps ψ_i(α, η) of every retained parameter θ_i, one grid per block.

The eigenshape of θ_i is the correction field its right singular vector makes
(Bottasso, Cacciola & Iriarte 2014, §3): ψ_i(α, η) = Σ_j B_j(α, η) V_ji over the lift
or the drag nodes j, with B_j the nodes' shape functions, in scale units per unit θ_i.
Each map covers the node range; the (α, η) points the operating points reach are dotted,
and those outside the node range are counted in the title instead of stretching the axes.

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.figure import Figure
from matplotlib.image import AxesImage
from matplotlib.patches import Rectangle

from calib.calibration.result import CalibrationResult
from calib.report.panels import DPI, Margins, tile_labels, title_height, wrap_title

MAX_COLUMNS = 4           # maps across: four keep a map over 180 px wide in a 1100 px report
MIN_WIDTH = 5.0           # narrowest figure [in] (title and axis labels fit)
PANEL_SIZE = (2.2, 1.5)    # one map [in]
MARGINS = Margins(left=0.6, right=1.05, bottom=0.5, top=0.8, wgap=0.22, hgap=0.3)
N_ALPHA, N_ETA = 97, 49    # mesh of the maps
NODE_FONTSIZE = 7          # node values beside the tiles [pt]


def eigen_mesh(result: CalibrationResult, n_alpha: int = N_ALPHA, n_eta: int = N_ETA, layout=None):
    """Uniform (α [deg], η [-]) mesh over the node range of the correction grid."""
    grid = (layout or result.layout).grid
    a, e = grid.alpha_nodes_deg, grid.eta_nodes
    return np.linspace(a[0], a[-1], n_alpha), np.linspace(e[0], e[-1], n_eta)


def seen_inside(result: CalibrationResult, layout=None):
    """(α, η) seen by the data inside the node range, and how many lie outside it.

    Parameters
    ----------
    result : CalibrationResult
    layout : NodeLayout, optional
        ``result.layout`` if already at hand.

    Returns
    -------
    alpha_deg, eta : ndarray
        Points inside the node range [deg], [-].
    n_outside : int
    """
    grid = (layout or result.layout).grid
    a, e = result.fit.alpha_seen, result.fit.eta_seen
    inside = ((a >= grid.alpha_nodes_deg[0]) & (a <= grid.alpha_nodes_deg[-1])
              & (e >= grid.eta_nodes[0]) & (e <= grid.eta_nodes[-1]))
    return a[inside], e[inside], int(np.count_nonzero(~inside))


def block_share(V: np.ndarray, layout, mode: int, block: str) -> float:
    """Fraction of the squared entries of singular vector ``V[:, mode]`` on ``block``'s nodes [-].

    Parameters
    ----------
    V : ndarray, shape (n_params, n_params)
        Right singular vectors (columns).
    layout : NodeLayout
    mode : int
    block : {"lift", "drag"}
    """
    idx = (layout.lift_index if block == "lift" else layout.drag_index).ravel()
    v = V[:, mode]
    total = float(v @ v)
    return float(np.sum(v[idx[idx >= 0]] ** 2) / total) if total > 0 else 0.0


def plot_eigenshapes(result: CalibrationResult, block: str = "lift", max_modes: int | None = None,
                     modes=None, which: str | None = None):
    """Eigenshape maps ψ_i(α, η) of the retained θ for one block, all in one grid.

    Parameters
    ----------
    result : CalibrationResult
    block : {"lift", "drag"}
    max_modes : int, optional
        Draw at most this many (default: every retained θ); the title states the count.
    modes : sequence of int, optional
        Draw these θ (0-based, e.g. every direction with s_i above a level) instead of the
        retained ones; ``which`` then says in the title what they are.
    which : str, optional

    Returns
    -------
    matplotlib.figure.Figure or None
        None when the model has no correction field.

    Notes
    -----
    The maps are small multiples drawn as tiles of one axes (one image, a frame, node lines
    and the seen points per tile), not one axes each: matplotlib spends most of a figure's
    time on axes and their ticks, and a 37-map grid of separate axes took seconds; for the
    same reason the node values are plain text beside short tick marks, not axis ticks.
    Every tile spans the node range: α along x, η = r/R along y, with the node values under
    the lowest tile of each column and left of the first column.
    """
    if block not in ("lift", "drag"):
        raise ValueError(f"block must be 'lift' or 'drag', got {block!r}")
    layout = result.layout
    if not layout.has_field:
        return None
    retained = np.flatnonzero(result.identifiability.retained) if modes is None else np.asarray(modes, int)
    modes = retained if max_modes is None else retained[:max_modes]
    a_seen, e_seen, n_out = seen_inside(result, layout)
    kind = which or "retained θ"
    how_many = (f"all {len(retained)} {kind}" if len(modes) == len(retained)
                else f"the first {len(modes)} of {len(retained)} {kind}")
    fig, ax, tiles = _tile_canvas(result, block, len(modes), how_many, a_seen.size, n_out)
    if not len(modes):
        ax.text(0.5, -0.5, "no retained parameter", ha="center", va="center")
        ax.set_xticks([])
        ax.set_yticks([])
        return fig
    im = _draw_tiles(ax, result, block, modes, tiles, a_seen, e_seen)
    _label_axes(fig, ax, im, tiles, block)
    return fig


@dataclass(frozen=True)
class _TileGrid:
    """Where the tiles of the eigenshape figure sit.

    Attributes
    ----------
    ncol, nrow : int
        Tiles across and down; each tile is a unit square of the one axes.
    gx, gy : float
        Gaps between tiles [tile units].
    width, height : float
        Figure size [in].
    margins : Margins
        Of the tile grid in the figure [in].
    """

    ncol: int
    nrow: int
    gx: float
    gy: float
    width: float
    height: float
    margins: Margins


def _tile_canvas(result: CalibrationResult, block: str, n_modes: int, how_many: str, n_seen: int,
                 n_out: int) -> tuple[Figure, Axes, _TileGrid]:
    """The titled figure, its one frameless axes spanning the tiles, and where the tiles sit.

    Parameters
    ----------
    result : CalibrationResult
    block : {"lift", "drag"}
    n_modes : int
        Maps drawn (0 gives one empty tile).
    how_many : str
        Which θ are drawn, in words for the title.
    n_seen, n_out : int
        (α, η) points seen by the data inside and outside the node range.
    """
    n = max(n_modes, 1)
    ncol = min(MAX_COLUMNS, n)
    nrow = int(np.ceil(n / ncol))
    w, h = PANEL_SIZE
    grid_width = ncol * w + (ncol - 1) * MARGINS.wgap
    # at least MIN_WIDTH wide (a grid of one or two maps centred), so title and labels fit
    pad = max(MIN_WIDTH - (MARGINS.left + grid_width + MARGINS.right), 0.0) / 2
    width = MARGINS.left + grid_width + MARGINS.right + 2 * pad
    title = wrap_title(f"{result.name}: {block} eigenshapes ψ_i(α, η) of {how_many} ({result.n_params} "
                       f"parameters)\ndots: {n_seen} (α, η) seen by the data inside the node range; {n_out} "
                       f"outside it (not drawn); grid lines: correction nodes", width, 9)
    m = replace(MARGINS, top=title_height(title, 9) + 0.3, left=MARGINS.left + pad, right=MARGINS.right + pad)
    gx, gy = m.wgap / w, m.hgap / h                        # gaps in tile units
    height = m.bottom + nrow * h + (nrow - 1) * m.hgap + m.top
    fig = Figure(figsize=(width, height), dpi=DPI)
    ax = fig.add_axes((m.left / width, m.bottom / height, (width - m.left - m.right) / width,
                       (height - m.bottom - m.top) / height))
    ax.set_xlim(0, ncol + (ncol - 1) * gx)
    ax.set_ylim(-(nrow + (nrow - 1) * gy), 0)
    for spine in ax.spines.values():
        spine.set_visible(False)
    fig.suptitle(title, fontsize=9, y=1 - 0.08 / height)
    return fig, ax, _TileGrid(ncol, nrow, gx, gy, width, height, m)


def _draw_tiles(ax: Axes, result: CalibrationResult, block: str, modes: np.ndarray, tiles: _TileGrid,
                a_seen: np.ndarray, e_seen: np.ndarray) -> AxesImage:
    """Draw one tile per θ in ``modes``: its map, node lines, frame, seen points and title.

    Parameters
    ----------
    ax : Axes
        The axes of :func:`_tile_canvas`.
    result : CalibrationResult
    block : {"lift", "drag"}
    modes : ndarray of int
        The θ drawn (0-based), in tile order.
    tiles : _TileGrid
    a_seen, e_seen : ndarray
        (α [deg], η [-]) seen by the data inside the node range.

    Returns
    -------
    AxesImage
        The last map (all share one colour scale).
    """
    layout = result.layout
    a_nodes, e_nodes = layout.grid.alpha_nodes_deg, layout.grid.eta_nodes
    alpha, eta = eigen_mesh(result, layout=layout)
    lift, drag = result.eigenshapes(alpha, eta, modes)
    shapes = lift if block == "lift" else drag
    vmax = max(float(np.abs(shapes).max()), 1e-12)
    ua = (a_nodes - a_nodes[0]) / (a_nodes[-1] - a_nodes[0])   # node positions in a tile [0, 1]
    ue = (e_nodes - e_nodes[0]) / (e_nodes[-1] - e_nodes[0])
    us_a = (a_seen - a_nodes[0]) / (a_nodes[-1] - a_nodes[0])
    us_e = (e_seen - e_nodes[0]) / (e_nodes[-1] - e_nodes[0])
    da, de = 0.5 / (alpha.size - 1), 0.5 / (eta.size - 1)  # half a mesh cell in tile units
    segments, frames, dots_x, dots_y, ticks = [], [], [], [], []
    for k, i in enumerate(modes):
        row, col = divmod(k, tiles.ncol)
        x0, y1 = col * (1 + tiles.gx), -row * (1 + tiles.gy)
        y0 = y1 - 1
        im = ax.imshow(shapes[k], extent=(x0 - da, x0 + 1 + da, y0 - de, y1 + de), origin="lower", aspect="auto",
                       cmap="RdBu_r", vmin=-vmax, vmax=vmax, interpolation="nearest")
        im.set_clip_path(Rectangle((x0, y0), 1, 1, transform=ax.transData))
        segments += [[(x0 + u, y0), (x0 + u, y1)] for u in ua[1:-1]]
        segments += [[(x0, y0 + u), (x0 + 1, y0 + u)] for u in ue[1:-1]]
        frames.append(Rectangle((x0, y0), 1, 1))
        dots_x.append(x0 + us_a)
        dots_y.append(y0 + us_e)
        share = block_share(result.identifiability.V, layout, i, block)
        ax.text(x0 + 0.5, y1 + 0.03,
                f"θ{i + 1}  σ={result.identifiability.sigma_theta[i]:.2g}  {100 * share:.0f}% {block}",
                ha="center", va="bottom", fontsize=7)
        if k + tiles.ncol >= len(modes):       # lowest tile of its column: α node values under it
            ticks += _alpha_node_values(ax, x0, y0, ua, a_nodes)
        if col == 0:                           # η node values left of the first column
            ticks += _eta_node_values(ax, x0, y0, ue, e_nodes)
    ax.add_collection(LineCollection(segments, colors="0.55", linewidths=0.3))
    ax.add_collection(LineCollection(ticks, colors="k", linewidths=0.6, clip_on=False))
    ax.add_collection(PatchCollection(frames, facecolor="none", edgecolor="0.2", linewidths=0.6, gid="tiles"))
    if a_seen.size:
        ax.plot(np.concatenate(dots_x), np.concatenate(dots_y), ",", color="k", alpha=0.35, rasterized=True)
    return im


def _alpha_node_values(ax: Axes, x0: float, y0: float, ua: np.ndarray, a_nodes: np.ndarray) -> list:
    """Write the α node values under the tile whose lower left corner is (x0, y0) [tile units].

    Parameters
    ----------
    ax : Axes
    x0, y0 : float
        Lower left corner of the tile [tile units].
    ua : ndarray
        Node positions across the tile [0, 1].
    a_nodes : ndarray
        Node values [deg].

    Returns
    -------
    list
        The tick marks' segments, for one LineCollection.
    """
    tick_y = 0.03 / PANEL_SIZE[1]                         # 0.03 in in tile units
    for u, text, ha in tile_labels(ua, a_nodes, PANEL_SIZE[0], NODE_FONTSIZE):
        ax.text(x0 + u, y0 - 1.6 * tick_y, text, ha=ha, va="top", fontsize=NODE_FONTSIZE)
    return [[(x0 + u, y0), (x0 + u, y0 - tick_y)] for u in ua]


def _eta_node_values(ax: Axes, x0: float, y0: float, ue: np.ndarray, e_nodes: np.ndarray) -> list:
    """Write the η node values left of the tile whose lower left corner is (x0, y0) [tile units].

    Parameters
    ----------
    ax : Axes
    x0, y0 : float
        Lower left corner of the tile [tile units].
    ue : ndarray
        Node positions up the tile [0, 1].
    e_nodes : ndarray
        Node values [-].

    Returns
    -------
    list
        The tick marks' segments, for one LineCollection.
    """
    tick_x = 0.03 / PANEL_SIZE[0]                         # 0.03 in in tile units
    va = {"left": "bottom", "center": "center", "right": "top"}
    for u, text, align in tile_labels(ue, e_nodes, PANEL_SIZE[1], NODE_FONTSIZE, along="y"):
        ax.text(x0 - 1.6 * tick_x, y0 + u, text, ha="right", va=va[align], fontsize=NODE_FONTSIZE)
    return [[(x0, y0 + u), (x0 - tick_x, y0 + u)] for u in ue]


def _label_axes(fig: Figure, ax: Axes, im: AxesImage, tiles: _TileGrid, block: str) -> None:
    """Axis labels (the node values stand beside the tiles, not as ticks) and the maps' colour bar.

    Parameters
    ----------
    fig : Figure
    ax : Axes
        The axes of :func:`_tile_canvas`.
    im : AxesImage
        A map of the shared colour scale.
    tiles : _TileGrid
    block : {"lift", "drag"}
    """
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_xlabel("α [deg] (every tile; values of the α nodes under the lowest tiles)", fontsize=7, labelpad=16)
    ax.set_ylabel("η = r/R [-] (every tile; values of the η nodes left)" if tiles.nrow > 1 else "η = r/R [-]",
                  fontsize=7, labelpad=22)
    m, width, height = tiles.margins, tiles.width, tiles.height
    cax = fig.add_axes(((width - m.right + 0.2) / width, m.bottom / height, 0.14 / width,
                        (height - m.bottom - m.top) / height))
    fig.colorbar(im, cax=cax)
    cax.tick_params(labelsize=6)
    cax.set_ylabel(f"ψ ({block}) [scale units per unit θ]", fontsize=7)
