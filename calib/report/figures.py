"""Figures of a calibration (matplotlib, Agg): the registry and the atomic writer.

Figures, by registry name:

- ``singular_values``: singular-value spectrum with the cut s = 1/σ̄,
- ``truncation``: the truncation criterion against the number retained (automatic truncation),
- ``eigenshapes_lift``, ``eigenshapes_drag``: eigenshape maps ψ_i(α, η) of every retained
  parameter, with the (α, η) points the data see,
- ``correlation``: Cramér–Rao correlation matrix, labelled by parameter,
- ``fit``: measured vs model before/after per channel with residual panels,
- ``polars``: corrected polars with confidence bands (and a known truth, if given).

PNG is written by default; SVG on request (``formats=("png", "svg")``). Every file is
written to a temporary name in its folder and renamed (:mod:`calib.report.atomic`), so an
interrupted run never leaves a truncated figure under a final name, and Ctrl-C while a
figure is drawn arrives as ``KeyboardInterrupt`` (:mod:`calib.report.interrupts`).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Callable

import matplotlib

matplotlib.use("Agg")

from calib.report.atomic import atomic_path  # noqa: E402
from calib.report.correlation_figure import plot_correlation  # noqa: E402
from calib.report.eigenshape_figures import plot_eigenshapes  # noqa: E402
from calib.report.fit_figures import plot_fit  # noqa: E402
from calib.report.interrupts import interrupts_as_keyboard_interrupt  # noqa: E402
from calib.report.panels import DPI  # noqa: E402
from calib.report.polar_figures import TruthField, plot_polars  # noqa: E402
from calib.report.spectrum_figures import plot_singular_values, plot_spectra, plot_truncation  # noqa: E402
from calib.result import CalibrationResult  # noqa: E402

FORMATS = ("png",)
ALL_FORMATS = ("png", "svg")
Progress = Callable[[str], None]


def _singular_values(result, truth=None):
    return plot_singular_values(result)


def _truncation(result, truth=None):
    return plot_truncation(result)


def _eigenshapes_lift(result, truth=None):
    return plot_eigenshapes(result, "lift")


def _eigenshapes_drag(result, truth=None):
    return plot_eigenshapes(result, "drag")


def _correlation(result, truth=None):
    return plot_correlation(result)


def _fit(result, truth=None):
    return plot_fit(result)


def _polars(result, truth=None):
    return plot_polars(result, truth=truth)


# name -> make(result, truth) -> Figure or None (None: the figure does not apply to this result)
FIGURES: dict[str, Callable] = {
    "singular_values": _singular_values,
    "truncation": _truncation,
    "eigenshapes_lift": _eigenshapes_lift,
    "eigenshapes_drag": _eigenshapes_drag,
    "correlation": _correlation,
    "fit": _fit,
    "polars": _polars,
}


def save_figure(fig, out_dir: str | Path, stem: str, formats=FORMATS, dpi: float = DPI) -> dict[str, Path]:
    """Save ``fig`` as ``out_dir/stem.<fmt>`` for each format, each atomically.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    out_dir : str or Path
        Created if missing.
    stem : str
        File name without extension.
    formats : sequence of {"png", "svg", "pdf"}
    dpi : float
        Resolution of PNG output and of rasterized parts of vector output [1/in].

    Returns
    -------
    dict
        format -> path.
    """
    out_dir = Path(out_dir)
    paths = {}
    with interrupts_as_keyboard_interrupt():
        for fmt in formats:
            path = out_dir / f"{stem}.{fmt}"
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as f:
                    fig.savefig(f, format=fmt, dpi=dpi)
            paths[fmt] = path
    _close(fig)
    return paths


def _close(fig) -> None:
    """Release a figure made through pyplot (figures made here are plain ``Figure`` objects)."""
    if getattr(fig.canvas, "manager", None) is not None:
        import matplotlib.pyplot as plt

        plt.close(fig)


def write_figures(result: CalibrationResult, out_dir: str | Path, prefix: str = "", formats=FORMATS,
                  truth: TruthField | None = None, progress: Progress | None = None) -> dict[str, dict[str, Path]]:
    """Write every figure of ``result`` that applies to it.

    Parameters
    ----------
    result : CalibrationResult
    out_dir : str or Path
    prefix : str
        Prepended to every file name.
    formats : sequence of str
        ``("png",)`` by default; add ``"svg"`` for vector copies (slower).
    truth : callable, optional
        ``truth(alpha_deg, eta) -> (dcl, dcd)``: the known correction field of a synthetic run,
        overlaid on the polar figure [-].
    progress : callable, optional
        Called with one line of text before the first and after every figure (e.g. ``print``).

    Returns
    -------
    dict
        Figure name -> {format: path}, in registry order.
    """
    out = {}
    t_start = time.perf_counter()
    if progress:
        progress(f"{result.name}: writing up to {len(FIGURES)} figures ({', '.join(formats)}) to {out_dir}")
    for k, (name, make) in enumerate(FIGURES.items()):
        t0 = time.perf_counter()
        with interrupts_as_keyboard_interrupt():
            fig = make(result, truth=truth)
            if fig is None:
                continue
            out[name] = save_figure(fig, out_dir, f"{prefix}{name}", formats)
        if progress:
            progress(f"{result.name}: figure {k + 1}/{len(FIGURES)} {name} ({time.perf_counter() - t0:.1f} s)")
    if progress:
        progress(f"{result.name}: {len(out)} figures in {time.perf_counter() - t_start:.1f} s")
    return out


__all__ = ["ALL_FORMATS", "FIGURES", "FORMATS", "plot_correlation", "plot_eigenshapes", "plot_fit", "plot_polars",
           "plot_singular_values", "plot_spectra", "plot_truncation", "save_figure", "write_figures"]
