"""Corrected polars C = C₀ + ΔC(α, η) with confidence bands at a few span stations.

Lift on top, drag below (one scale per row), one tile per η station, on the α range of
the correction nodes (the corrections are defined there; the α the data reach at each
station is stated in the tile title and shaded where it overlaps the node range). Where
more than half of a band's variance comes from the prior (the data say little) the band
is shaded in another colour. For a synthetic run a known truth ΔC(α, η) can be overlaid.

Each row is one axes with the stations side by side as tiles (α mapped onto [0, 1] per
tile, node-range ticks drawn as text): ten separate axes cost three quarters of this
figure's time in matplotlib's tick machinery.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.patches import Rectangle
from matplotlib.ticker import MaxNLocator

from calib.calibration.result import CalibrationResult
from calib.report.panels import Margins, panel_grid, settle_labels, tile_labels, title_height, wrap_title

TruthField = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]


def station_columns(eta: np.ndarray, max_stations: int) -> np.ndarray:
    """Indices of at most ``max_stations`` η stations spread over ``eta``."""
    return np.unique(np.linspace(0, eta.size - 1, min(max_stations, eta.size)).round().astype(int))


def _seen_near(result: CalibrationResult, eta: np.ndarray, j: int) -> np.ndarray:
    """α [deg] seen by the data within half a station spacing of ``eta[j]``."""
    if not result.fit.alpha_seen.size:
        return np.zeros(0)
    half = 0.5 * float(np.min(np.diff(eta))) if eta.size > 1 else 1.0
    return result.fit.alpha_seen[np.abs(result.fit.eta_seen - eta[j]) <= half]


def alpha_ticks(a0: float, a1: float) -> np.ndarray:
    """About five round α values inside [a0, a1] [deg]."""
    t = MaxNLocator(5).tick_values(a0, a1)
    return t[(t >= a0 - 1e-9) & (t <= a1 + 1e-9)]


TILE_SIZE = (2.6, 2.1)     # one station's tile [in]
TILE_GAP = 0.15            # between tiles [in]
GAP = TILE_GAP / TILE_SIZE[0]                             # gap in tile units
MARGINS = Margins(left=0.75, right=0.2, bottom=0.55, top=0.75, hgap=0.55)


def plot_polars(result: CalibrationResult, max_stations: int = 5, truth: TruthField | None = None):
    """Corrected polars with confidence bands, lift (top row) and drag (bottom row).

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
        None when the result has no polar bands. Its two axes (lift, drag) hold one tile
        per station: station ``col`` spans x ∈ [col (1 + gap), col (1 + gap) + 1] with
        x = (α − α₀)/(α₁ − α₀) inside; every drawn line carries the gid
        ``"<kind>:<row>:<col>"`` (kind: nominal, calibrated, truth).
    """
    pb = result.uncertainty.polar_bands
    if not pb:
        return None
    alpha_deg, eta = np.asarray(pb["alpha_deg"], float), np.asarray(pb["eta"], float)
    idx = station_columns(eta, max_stations)
    fig, axes = _polar_canvas(result, alpha_deg, idx.size, truth is not None)
    stations = _stations(result, alpha_deg, eta, idx, truth)
    for row, letter in enumerate(("cl", "cd")):
        _draw_row(axes[row, 0], stations, row, letter)
        _style_row(axes[row, 0], idx.size, row, letter)
    settle_labels(fig)
    return fig


def _polar_canvas(result: CalibrationResult, alpha_deg: np.ndarray, n: int, with_truth: bool):
    """The titled figure with one axes per row (lift, drag), each ``n`` tiles wide.

    Parameters
    ----------
    result : CalibrationResult
    alpha_deg : ndarray
        α of the bands [deg].
    n : int
        Stations drawn.
    with_truth : bool
        A known truth is overlaid (the title says so).

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (2, 1)
    """
    tile_w, tile_h = TILE_SIZE
    row_w = n * tile_w + (n - 1) * TILE_GAP
    what = "corrected polars" + ("" if "cl0" in result.uncertainty.polar_bands else " (corrections only)")
    width = MARGINS.left + row_w + MARGINS.right
    span = f"{alpha_deg[0]:g}…{alpha_deg[-1]:g}°"
    title = wrap_title(f"{result.name}: {what} on the α range of the correction nodes ({span})"
                       + ("; dashed: known truth" if with_truth else ""), width, 9)
    fig, axes = panel_grid(2, 1, (row_w, tile_h), replace(MARGINS, top=title_height(title, 9) + 0.45))
    fig.suptitle(title, fontsize=9, y=1 - 0.08 / fig.get_size_inches()[1])
    return fig, axes


@dataclass(frozen=True)
class _Stations:
    """What the tiles of one polar figure share.

    Attributes
    ----------
    bands : dict
        ``result.polar_bands``.
    alpha_deg : ndarray
        α of the bands [deg].
    eta : ndarray
        η of every band station [-].
    idx : ndarray of int
        The stations drawn, as indices into ``eta``.
    u : ndarray
        ``alpha_deg`` mapped onto [0, 1] (x in a tile).
    a_ticks, ua_ticks : ndarray
        Round α values [deg] and their x in a tile [0, 1].
    seen : list of ndarray
        α seen by the data near each drawn station [deg].
    truth : list of ndarray or None
        Known ΔC_L and ΔC_D at the drawn stations, each shape (n_drawn, n_alpha) [-].
    confidence : float
        Of the bands [-].
    """

    bands: dict
    alpha_deg: np.ndarray
    eta: np.ndarray
    idx: np.ndarray
    u: np.ndarray
    a_ticks: np.ndarray
    ua_ticks: np.ndarray
    seen: list
    truth: list | None
    confidence: float


def _stations(result: CalibrationResult, alpha_deg: np.ndarray, eta: np.ndarray, idx: np.ndarray,
              truth: TruthField | None) -> _Stations:
    """The shared quantities of :class:`_Stations` for the drawn stations ``idx``."""
    pb = result.uncertainty.polar_bands
    conf = float(pb.get("confidence", 0.95))
    truth_d = None
    if truth is not None:
        A, E = np.meshgrid(alpha_deg, eta[idx])
        truth_d = [np.broadcast_to(np.asarray(t, float), A.shape) for t in truth(A, E)]
    u = (alpha_deg - alpha_deg[0]) / (alpha_deg[-1] - alpha_deg[0])
    a_ticks = alpha_ticks(alpha_deg[0], alpha_deg[-1])
    ua_ticks = (a_ticks - alpha_deg[0]) / (alpha_deg[-1] - alpha_deg[0])
    seen = [_seen_near(result, eta, j) for j in idx]
    return _Stations(pb, alpha_deg, eta, idx, u, a_ticks, ua_ticks, seen, truth_d, conf)


def _draw_row(ax: Axes, st: _Stations, row: int, letter: str) -> None:
    """Draw one row's tiles (lift: ``letter`` "cl", drag: "cd"), framed, with their labels.

    The top row titles each tile with its η and the α seen; the bottom row writes the α values
    under each tile.

    Parameters
    ----------
    ax : Axes
        The row's axes.
    st : _Stations
    row : int
        0 (lift) or 1 (drag).
    letter : {"cl", "cd"}
    """
    xt = ax.get_xaxis_transform()                    # x in data, y in axes fraction
    frames, vgrid, marks = [], [], []
    for col, j in enumerate(st.idx):
        x0 = col * (1 + GAP)
        _draw_curves(ax, st, row, col, letter)
        s = st.seen[col]
        _shade_seen(ax, st, x0, s, col == 0)
        frames.append(Rectangle((x0, 0), 1, 1))
        vgrid += [[(x0 + t, 0), (x0 + t, 1)] for t in st.ua_ticks]
        if row == 0:
            ax.text(x0 + 0.5, 1.02, f"η = {st.eta[j]:.2f}" + (f"; α seen {s.min():.0f}…{s.max():.0f}°" if s.size
                                                              else "; no α seen"),
                    transform=xt, ha="center", va="bottom", fontsize=8)
        else:
            marks += [[(x0 + t, 0), (x0 + t, -0.02)] for t in st.ua_ticks]
            for t, text, ha in tile_labels(st.ua_ticks, st.a_ticks, TILE_SIZE[0], 7):
                ax.text(x0 + t, -0.035, text, transform=xt, ha=ha, va="top", fontsize=7)
            ax.text(x0 + 0.5, -0.13, "α [deg]", transform=xt, ha="center", va="top", fontsize=8)
    n = st.idx.size
    for k in range(n - 1):                           # white gaps between tiles, over the y grid
        ax.axvspan(k * (1 + GAP) + 1, (k + 1) * (1 + GAP), color="white", lw=0, zorder=0.8)
    ax.add_collection(LineCollection(vgrid, colors="0.85", linewidths=0.6, transform=xt, zorder=0.7))
    ax.add_collection(PatchCollection(frames, facecolor="none", edgecolor="k", linewidths=0.8, transform=xt,
                                      zorder=2.5, gid="tiles"))
    if marks:
        ax.add_collection(LineCollection(marks, colors="k", linewidths=0.8, transform=xt, clip_on=False))


def _draw_curves(ax: Axes, st: _Stations, row: int, col: int, letter: str) -> None:
    """Nominal, band (shaded again where the prior sets it), calibrated and any known truth of one tile.

    Parameters
    ----------
    ax : Axes
    st : _Stations
    row, col : int
        Row (0 lift, 1 drag) and tile of the station drawn.
    letter : {"cl", "cd"}
    """
    pb, j, first = st.bands, st.idx[col], col == 0
    x = col * (1 + GAP) + st.u
    base = np.asarray(pb[f"{letter}0"])[j] if f"{letter}0" in pb else np.zeros_like(st.alpha_deg)
    d = np.asarray(pb[f"d{letter}"])[j]
    if f"d{letter}_lower" in pb:                 # the drag band bounded by C_D,min
        lo, hi = np.asarray(pb[f"d{letter}_lower"])[j], np.asarray(pb[f"d{letter}_upper"])[j]
    else:                                        # a result saved before the bounded bands
        hw = np.asarray(pb[f"d{letter}_half_width"])[j]
        lo, hi = d - hw, d + hw
    ax.plot(x, base, color="0.5", lw=1, label="nominal" if first else "_nolegend_", gid=f"nominal:{row}:{col}")
    ax.fill_between(x, base + lo, base + hi, color="C0", alpha=0.25, lw=0, gid=f"band:{row}:{col}",
                    label=f"{100 * st.confidence:.0f}% band" if first else "_nolegend_")
    frac_key = f"d{letter}_prior_fraction"
    if frac_key in pb:
        prior_dom = np.asarray(pb[frac_key])[j] > 0.5
        if prior_dom.any():
            ax.fill_between(x, base + lo, base + hi, where=prior_dom, color="C1", alpha=0.25, lw=0,
                            label="band set by the prior (data say little)" if first else "_nolegend_")
    ax.plot(x, base + d, color="C0", lw=1.2, label="calibrated" if first else "_nolegend_",
            gid=f"calibrated:{row}:{col}")
    if st.truth is not None:
        ax.plot(x, base + st.truth[row][col], "--", color="k", lw=1, label="truth" if first else "_nolegend_",
                gid=f"truth:{row}:{col}")


def _shade_seen(ax: Axes, st: _Stations, x0: float, seen: np.ndarray, first: bool) -> None:
    """Shade the part of the tile at ``x0`` [tile units] whose α [deg] the data reach (``seen``)."""
    alpha_deg = st.alpha_deg
    if seen.size:
        lo, hi = max(seen.min(), alpha_deg[0]), min(seen.max(), alpha_deg[-1])
        if lo < hi:
            ulo, uhi = (np.array([lo, hi]) - alpha_deg[0]) / (alpha_deg[-1] - alpha_deg[0])
            ax.axvspan(x0 + ulo, x0 + uhi, color="C2", alpha=0.08, lw=0,
                       label="α seen" if first else "_nolegend_")


def _style_row(ax: Axes, n: int, row: int, letter: str) -> None:
    """Axis limits, y grid and label of a row of ``n`` tiles; the legend in the top row."""
    xt = ax.get_xaxis_transform()
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_xlim(0, n + (n - 1) * GAP)
    ax.set_xticks([])
    ax.yaxis.set_major_locator(MaxNLocator(5))
    ax.yaxis.grid(True, color="0.85", lw=0.6)
    ax.set_axisbelow(True)
    ax.tick_params(axis="y", labelsize=7)
    ax.set_ylabel("C_L [-]" if letter == "cl" else "C_D [-]", fontsize=8)
    if row == 0:
        ax.legend(fontsize=7, loc="lower right", bbox_to_anchor=(1.0, 0.02), bbox_transform=xt)
