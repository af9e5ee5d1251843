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

from calib.calibration.result import CalibrationResult  # noqa: E402
from calib.report.atomic import atomic_path  # noqa: E402
from calib.report.correlation_figure import plot_correlation  # noqa: E402
from calib.report.eigenshape_figures import plot_eigenshapes  # noqa: E402
from calib.report.fit_figures import plot_fit  # noqa: E402
from calib.report.interrupts import interrupts_as_keyboard_interrupt  # noqa: E402
from calib.report.panels import DPI  # noqa: E402
from calib.report.parallel import default_workers, fork_available, run_forked  # noqa: E402
from calib.report.polar_figures import TruthField, plot_polars  # noqa: E402
from calib.report.spectrum_figures import plot_singular_values, plot_truncation  # noqa: E402

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


def figure_costs(result: CalibrationResult) -> dict[str, float]:
    """Relative drawing cost of each registered figure of ``result`` (to balance workers).

    About 0.2 s of one core per unit on the wind-tunnel study (measured); eigenshape maps
    scale with the retained θ, the fit with the channels.
    """
    costs = {name: 1.0 for name in FIGURES}
    per_block = 1.0 + result.n_retained / 8.0
    costs.update({"singular_values": 0.7, "truncation": 0.7, "correlation": 1.5, "polars": 2.0,
                  "eigenshapes_lift": per_block, "eigenshapes_drag": per_block,
                  "fit": 1.0 + 0.45 * len(result.channels)})
    return {name: costs[name] for name in FIGURES}


def write_figures(result: CalibrationResult, out_dir: str | Path, prefix: str = "", formats=FORMATS,
                  truth: TruthField | None = None, progress: Progress | None = None,
                  workers: int | None = None) -> dict[str, dict[str, Path]]:
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
    workers : int, optional
        Processes drawing figures side by side (default: one per available core, at most
        :data:`calib.report.parallel.MAX_WORKERS`); 1 draws them here. Workers are forked
        only where that is safe (:func:`calib.report.parallel.fork_available`).

    Returns
    -------
    dict
        Figure name -> {format: path}, in registry order.
    """
    names = list(FIGURES)
    n_workers = default_workers(len(names)) if workers is None else max(1, int(workers))
    parallel = n_workers > 1 and fork_available()
    t_start = time.perf_counter()
    if progress:
        how = f", {n_workers} processes" if parallel else ""
        progress(f"{result.name}: writing up to {len(names)} figures ({', '.join(formats)}{how}) to {out_dir}")

    def render(name: str):
        with interrupts_as_keyboard_interrupt():
            fig = FIGURES[name](result, truth=truth)
            if fig is None:
                return None
            return {fmt: str(p) for fmt, p in save_figure(fig, out_dir, f"{prefix}{name}", formats).items()}

    done = []

    def on_done(name: str, paths, seconds: float) -> None:
        done.append(name)
        if progress and paths is not None:
            progress(f"{result.name}: figure {len(done)}/{len(names)} {name} ({seconds:.1f} s)")

    if parallel:
        written = run_forked(figure_costs(result), render, n_workers, on_done)
    else:
        written = {}
        for name in names:
            t0 = time.perf_counter()
            written[name] = render(name)
            on_done(name, written[name], time.perf_counter() - t0)
    out = {name: {fmt: Path(p) for fmt, p in paths.items()} for name, paths in written.items() if paths is not None}
    if progress:
        progress(f"{result.name}: {len(out)} figures in {time.perf_counter() - t_start:.1f} s")
    return out


__all__ = ["ALL_FORMATS", "FIGURES", "FORMATS", "save_figure", "write_figures"]
