"""What makes a report figure unreadable, measured on the drawn figure (matplotlib, Agg).

A figure is checked as the reports show it: saved at ``dpi`` and scaled down to the width
of the reports' content column when wider (``img{max-width:100%}`` in a 1100 px body with
1 em padding, :data:`SHOWN_WIDTH_PX`). What fails:

- two texts whose drawn boxes overlap (tick labels of neighbouring panels running together,
  a label over a title), or a text cut off by the figure's edge;
- a panel narrower than :data:`MIN_PANEL_PX` as shown: an axes other than a colour bar, or
  one tile of a figure that draws small multiples as tiles of one axes (the frames of its
  tiles are a collection with the gid ``"tiles"``);
- a text smaller than :data:`MIN_FONT_PX` as shown;
- an axis whose numbers carry a scale factor or offset (``1e6`` at the axis end) instead
  of a unit prefix in the label.
"""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection
from matplotlib.text import Text

SHOWN_WIDTH_PX = 1068      # the reports' content column [px]: a 1100 px body less 2 x 16 px padding
MIN_PANEL_PX = 180         # narrowest readable panel as shown [px]: about six across the column
MIN_FONT_PX = 7.0          # smallest readable font size as shown [px] (about 5.3 pt at 96 dpi)
OVERLAP_PX = 1.0           # boxes overlapping by less than this in either direction are touching, not overlapping


def _texts(fig, renderer) -> list[tuple[Text, np.ndarray]]:
    """Every drawn, non-empty text of ``fig`` with its box (x0, y0, x1, y1) [px at fig.dpi].

    Tick labels count only for the ticks an axis draws (inside its view interval): matplotlib
    keeps label objects for located ticks outside it too.
    """
    ticks, drawn = set(), set()
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                ticks.update((id(tick.label1), id(tick.label2)))
            for tick in axis._update_ticks():
                drawn.update((id(tick.label1), id(tick.label2)))
    out = []
    for t in fig.findobj(Text):
        if not t.get_visible() or not t.get_text().strip() or (id(t) in ticks and id(t) not in drawn):
            continue
        if t.axes is not None and not t.axes.get_visible():
            continue
        box = t.get_window_extent(renderer)
        if box.width <= 0 or box.height <= 0:
            continue
        out.append((t, np.array([box.x0, box.y0, box.x1, box.y1])))
    return out


def _shown_scale(fig, dpi: float, shown_width_px: float) -> float:
    """Factor from saved pixels to shown pixels (at most 1: a narrow figure is not enlarged)."""
    return min(1.0, shown_width_px / (fig.get_figwidth() * dpi))


def _name(t: Text) -> str:
    text = " ".join(t.get_text().split())
    return repr(text if len(text) <= 40 else text[:37] + "...")


def figure_problems(fig, dpi: float = 100.0, shown_width_px: float = SHOWN_WIDTH_PX) -> list[str]:
    """What makes ``fig`` hard to read as the reports show it (empty when nothing does).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    dpi : float
        Resolution the figure is saved at [1/in].
    shown_width_px : float
        Width it is shown at, at most [px].

    Returns
    -------
    list of str
        One line per problem, naming the texts or panels.
    """
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    scale = _shown_scale(fig, dpi, shown_width_px)
    to_shown = dpi / fig.dpi * scale                        # drawn px -> shown px
    problems = []
    texts = _texts(fig, renderer)
    W, H = fig.bbox.width, fig.bbox.height
    for t, (x0, y0, x1, y1) in texts:
        if x0 < -OVERLAP_PX or y0 < -OVERLAP_PX or x1 > W + OVERLAP_PX or y1 > H + OVERLAP_PX:
            problems.append(f"text {_name(t)} is cut off by the figure's edge")
        shown = t.get_fontsize() / 72.0 * dpi * scale
        if shown < MIN_FONT_PX:
            problems.append(f"text {_name(t)} is {shown:.1f} px high as shown (< {MIN_FONT_PX:g} px)")
    if texts:
        boxes = np.array([b for _, b in texts])
        dx = np.minimum(boxes[:, None, 2], boxes[None, :, 2]) - np.maximum(boxes[:, None, 0], boxes[None, :, 0])
        dy = np.minimum(boxes[:, None, 3], boxes[None, :, 3]) - np.maximum(boxes[:, None, 1], boxes[None, :, 1])
        hit = np.triu((dx > OVERLAP_PX) & (dy > OVERLAP_PX), k=1)
        for i, j in zip(*np.nonzero(hit)):
            problems.append(f"texts {_name(texts[i][0])} and {_name(texts[j][0])} overlap")
    for tiles in fig.findobj(lambda a: isinstance(a, Collection) and a.get_gid() == "tiles"):
        trans = tiles.get_transform()
        widths = [path.get_extents(trans).width * to_shown for path in tiles.get_paths()]
        if widths and min(widths) < MIN_PANEL_PX:
            problems.append(f"tiles of {len(widths)} are {min(widths):.0f} px wide as shown (< {MIN_PANEL_PX} px)")
    for ax in fig.axes:
        if hasattr(ax, "_colorbar") or not ax.get_visible():      # a colour bar is narrow by design
            continue
        width = ax.get_window_extent(renderer).width * to_shown
        if width < MIN_PANEL_PX:
            problems.append(f"panel {_name(Text(text=ax.get_title() or ax.get_ylabel() or '?'))} is {width:.0f} px "
                            f"wide as shown (< {MIN_PANEL_PX} px)")
        for axis, which in ((ax.xaxis, "x"), (ax.yaxis, "y")):
            offset = axis.get_offset_text()
            if offset.get_visible() and offset.get_text().strip():
                problems.append(f"the {which} axis of panel {_name(Text(text=ax.get_title() or ax.get_ylabel()))} "
                                f"carries a scale factor or offset {offset.get_text()!r} instead of a unit prefix")
    return problems
