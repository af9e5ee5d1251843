"""Figure layout for the report: grids fixed in inches, lean ticks, labels placed without measuring.

Most of a matplotlib figure's time goes into laying out text, not into drawing data.
Constrained layout measures every tick label of every panel before drawing and took about
half of the report's time; a grid whose panels, gaps and margins are given in inches lays
out in no time and looks the same from one result to the next. Each tick is several
artists, so axes get about five; axis labels sit at offsets estimated from their tick
labels' length instead of from rendered extents; titles are wrapped to the figure width.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter, LogLocator, MaxNLocator, NullLocator
from matplotlib.transforms import ScaledTranslation

DPI = 100


@dataclass(frozen=True)
class Margins:
    """Figure margins and gaps between panels [in]."""

    left: float = 0.75
    right: float = 0.2
    bottom: float = 0.55
    top: float = 0.45
    wgap: float = 0.6
    hgap: float = 0.55


def panel_grid(nrow: int, ncol: int, panel_size: tuple[float, float], margins: Margins = Margins(),
               n_panels: int | None = None):
    """A figure with an ``nrow`` × ``ncol`` grid of axes.

    Parameters
    ----------
    nrow, ncol : int
    panel_size : (float, float)
        Width and height of one panel [in].
    margins : Margins
        Outer margins and gaps [in].
    n_panels : int, optional
        Create only the first ``n_panels`` axes in row order (the others are None).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes or None, shape (nrow, ncol)
    """
    w, h = panel_size
    width = margins.left + ncol * w + (ncol - 1) * margins.wgap + margins.right
    height = margins.bottom + nrow * h + (nrow - 1) * margins.hgap + margins.top
    fig = Figure(figsize=(width, height), dpi=DPI)
    axes = np.empty((nrow, ncol), dtype=object)
    n_panels = nrow * ncol if n_panels is None else n_panels
    for i in range(nrow):
        for j in range(ncol):
            if i * ncol + j >= n_panels:
                continue
            x0 = margins.left + j * (w + margins.wgap)
            y0 = height - margins.top - i * (h + margins.hgap) - h
            axes[i, j] = fig.add_axes((x0 / width, y0 / height, w / width, h / height))
    return fig, axes


def single_panel(size: tuple[float, float] = (6.4, 3.6), margins: Margins = Margins(left=0.9, bottom=0.6,
                                                                                     top=0.4)):
    """A figure of total ``size`` [in] with one axes inside fixed margins."""
    width, height = size
    m = margins
    fig = Figure(figsize=size, dpi=DPI)
    ax = fig.add_axes((m.left / width, m.bottom / height, 1 - (m.left + m.right) / width,
                       1 - (m.bottom + m.top) / height))
    return fig, ax


def colorbar_axes(fig: Figure, axes, width: float = 0.14, pad: float = 0.15):
    """An axes for a colorbar right of ``axes`` (spanning their height) [in]."""
    boxes = [ax.get_position() for ax in np.ravel(axes) if ax is not None]
    x1 = max(b.x1 for b in boxes)
    y0, y1 = min(b.y0 for b in boxes), max(b.y1 for b in boxes)
    fw, _ = fig.get_size_inches()
    return fig.add_axes((x1 + pad / fw, y0, width / fw, y1 - y0))


def lean_ticks(ax, nbins: int = 5) -> None:
    """At most about ``nbins`` ticks per axis (each tick is several artists to build and draw)."""
    ax.xaxis.set_major_locator(MaxNLocator(nbins))
    ax.yaxis.set_major_locator(MaxNLocator(nbins))


#: Units that take an SI prefix on their first symbol (channel units of calib's outputs).
PREFIXABLE_UNITS = ("W", "N", "N m", "N/m", "Pa", "J")
_PREFIXES = ((1e9, "G"), (1e6, "M"), (1e3, "k"))


def unit_prefix(unit: str, values) -> tuple[float, str]:
    """The SI prefix that brings ``values`` of ``unit`` to below 1000, as (divisor, prefixed unit).

    ``unit_prefix("W", [2e5, 5.1e6])`` is ``(1e6, "MW")`` and ``unit_prefix("N m", [3e4])``
    ``(1e3, "kN m")``: an axis reads 5.1 MW, not 5.1 with "1e6" at its end. Units outside
    :data:`PREFIXABLE_UNITS`, or values below 1000 (or none finite), are left as they are
    (divisor 1).

    Parameters
    ----------
    unit : str
    values : array_like
        In ``unit``; NaN ignored.
    """
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v)]
    if unit not in PREFIXABLE_UNITS or not v.size:
        return 1.0, unit
    top = float(v.max())
    for factor, prefix in _PREFIXES:
        if top >= factor:
            return factor, prefix + unit
    return 1.0, unit


def plain_numbers(ax) -> None:
    """Tick labels without a scale factor or offset at the axis end (``1e6``, ``+1.2e3``)."""
    for axis in (ax.xaxis, ax.yaxis):
        formatter = axis.get_major_formatter()
        if hasattr(formatter, "set_useOffset"):
            formatter.set_useOffset(False)
            formatter.set_scientific(False)


CHAR_WIDTH = 0.62            # width of a digit or sign [em]


def tile_labels(positions, values, tile_width: float, fontsize: float, pad: float = 0.5, along: str = "x"):
    """Which values to write along one edge of a tile, and how to align them, so that none
    runs into another or into the next tile's.

    The first value is aligned to start at the tile's left edge and the last to end at its
    right edge (centred values of two neighbouring tiles ran together, "8.22-3.03"); the
    inner values are centred and kept from the left while they clear the one kept before
    and the last one by ``pad`` em.

    Parameters
    ----------
    positions : array_like
        Where each value belongs across the tile, in [0, 1], increasing.
    values : array_like of float
    tile_width : float
        Width of the tile as drawn [in].
    fontsize : float
        Of the labels [pt].
    pad : float
        Least space between two labels [em].
    along : {"x", "y"}
        Labels side by side along a tile's width (a label's extent is its text's width) or
        stacked up its height (``tile_width`` is then the height; an extent is one line,
        and the alignments "left", "center", "right" mean "bottom", "center", "top").

    Returns
    -------
    list of (float, str, str)
        (position, text, alignment) of each label to write.
    """
    u = np.asarray(positions, float)
    texts = [f"{v:g}" for v in values]
    if not texts:
        return []
    em = fontsize / 72.0 / tile_width                      # one em in tile units
    widths = [(CHAR_WIDTH * len(t) if along == "x" else 1.2) * em for t in texts]

    def extent(k, ha):
        return (u[k], u[k] + widths[k]) if ha == "left" else \
            (u[k] - widths[k], u[k]) if ha == "right" else (u[k] - widths[k] / 2, u[k] + widths[k] / 2)

    last = len(texts) - 1
    out = [(u[0], texts[0], "left")]
    if last == 0:
        return out
    end = extent(last, "right")
    right_edge = extent(0, "left")[1]
    for k in range(1, last):
        lo, hi = extent(k, "center")
        if lo >= right_edge + pad * em and hi <= end[0] - pad * em:
            out.append((u[k], texts[k], "center"))
            right_edge = hi
    if end[0] >= extent(0, "left")[1] + pad * em:
        out.append((u[last], texts[last], "right"))
    return out


def spread(positions, gap: float, lo: float, hi: float) -> np.ndarray:
    """Label positions moved apart as little as needed to be at least ``gap`` apart, within [lo, hi].

    A forward pass pushes each position past its predecessor, a backward pass pulls them
    back inside ``hi``; positions already ``gap`` apart are not moved. When ``hi - lo`` is
    too short for all of them, they are spaced evenly over it.

    Parameters
    ----------
    positions : array_like
        Increasing label positions (any unit).
    gap : float
        Least distance between two labels (same unit).
    lo, hi : float
        Range the labels stay in.

    Returns
    -------
    ndarray
    """
    p = np.asarray(positions, float).copy()
    if p.size < 2:
        return p
    if (p.size - 1) * gap > hi - lo:
        return np.linspace(lo, hi, p.size)
    for k in range(1, p.size):
        p[k] = max(p[k], p[k - 1] + gap)
    p[-1] = min(p[-1], hi)
    for k in range(p.size - 2, -1, -1):
        p[k] = min(p[k], p[k + 1] - gap)
    p[0] = max(p[0], lo)
    for k in range(1, p.size):
        p[k] = max(p[k], p[k - 1] + gap)
    return p


def lean_log_ticks(ax, numticks: int = 8) -> None:
    """Decade ticks only on a logarithmic y axis, labelled as plain numbers (``100``, ``0.01``, ``1e-05``).

    Minor ticks over many decades cost more than the plot, and the default 10ⁿ labels
    start matplotlib's mathtext parser (a quarter of a second on first use).
    """
    ax.yaxis.set_major_locator(LogLocator(base=10.0, numticks=numticks))
    ax.yaxis.set_minor_locator(NullLocator())
    ax.yaxis.set_major_formatter(FuncFormatter(_plain_number))


def _plain_number(value: float, _pos=None) -> str:
    return f"{value:g}"


def wrap_title(text: str, width: float, fontsize: float) -> str:
    """``text`` wrapped to a figure ``width`` [in] at ``fontsize`` [pt] (existing line breaks kept)."""
    per_line = max(20, int(width * 72.0 / (0.55 * fontsize)))
    return "\n".join(textwrap.fill(line, per_line) for line in text.split("\n"))


def title_height(text: str, fontsize: float) -> float:
    """Height of a (wrapped) title [in] with a small margin."""
    return (text.count("\n") + 1) * fontsize * 1.3 / 72.0 + 0.15


def settle_labels(fig: Figure, ticklabel_size: float = 7.0) -> None:
    """Place every axis label at a fixed offset from its axes, from an estimate of the tick labels.

    By default matplotlib measures the rendered tick labels of an axis (and of every axis
    sharing it) at each draw to place the axis label, which took about a tenth of the
    report's time; here the offset follows from the longest tick label's character count
    (digits are about 0.62 em wide) and the standard tick length, pad and label pad.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    ticklabel_size : float
        Font size of the tick labels [pt] (an upper bound is fine: labels move out a little).
    """
    for ax in fig.axes:
        for axis, is_x in ((ax.xaxis, True), (ax.yaxis, False)):
            lo, hi = sorted(axis.get_view_interval())
            locs = [v for v in axis.get_majorticklocs() if lo - 1e-9 * abs(hi - lo) <= v <= hi + 1e-9 * abs(hi - lo)]
            labels = axis.get_major_formatter().format_ticks(locs) if locs else []
            chars = max((4 if t.startswith("$") else len(t) for t in labels), default=0)
            if is_x:
                offset = (7.0 + 1.25 * ticklabel_size + 4.0) / 72.0 if chars else 4.0 / 72.0
                trans = ax.transAxes + ScaledTranslation(0, -offset, fig.dpi_scale_trans)
                axis.set_label_coords(0.5, 1.0 if axis.get_label_position() == "top" else 0.0, trans)
            else:
                offset = (7.0 + 0.62 * ticklabel_size * chars + 4.0) / 72.0
                right = axis.get_label_position() == "right"
                trans = ax.transAxes + ScaledTranslation(offset if right else -offset, 0, fig.dpi_scale_trans)
                axis.set_label_coords(1.0 if right else 0.0, 0.5, trans)
