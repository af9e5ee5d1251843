"""A measured wind-speed histogram as the AEP's wind distribution (issue 41 item 4): :func:`read_wind_histogram`.

The CSV holds one row per wind-speed bin: its centre ``wind_speed`` [m/s] and either ``hours`` [h] or
``frequency`` [-] (a column name may carry its unit in brackets, ``wind_speed [m/s]``); lines starting
with ``#`` are comments. Hours are normalized to frequencies: the AEP is per year of 8760 h, as for the
Rayleigh and Weibull distributions. The bins' edges are the midpoints between centres (the outer ones
half a spacing out), and within a bin the wind speed is taken uniform, so the cumulative distribution
F is piecewise linear through the edges; the IEC 61400-12-1 formula (:func:`calib.powercurve.aep.aep_weights`)
then evaluates F at the power curve's own bins, which need not be the histogram's.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.errors import InputError

__all__ = ["WindHistogram", "read_wind_histogram"]


@dataclass(frozen=True)
class WindHistogram:
    """A measured wind-speed histogram.

    Attributes
    ----------
    wind_speed : ndarray, shape (n,)
        Bin centres [m/s], increasing.
    frequency : ndarray, shape (n,)
        Share of the time in each bin [-], summing to 1.
    source : str
        The file.
    hours : float or None
        The hours the file stated in total [h] (None when it gave frequencies).
    """

    wind_speed: np.ndarray
    frequency: np.ndarray
    source: str
    hours: float | None = None

    @property
    def edges(self) -> np.ndarray:
        """Bin edges [m/s]: midpoints between centres, the outer ones half a spacing out (not below 0)."""
        v = self.wind_speed
        mid = 0.5 * (v[1:] + v[:-1])
        return np.concatenate([[max(v[0] - (mid[0] - v[0]), 0.0)], mid, [v[-1] + (v[-1] - mid[-1])]])

    def cdf(self, v):
        """Cumulative distribution F(v), piecewise linear through the edges (uniform within a bin) [-]."""
        F = np.concatenate([[0.0], np.cumsum(self.frequency)])
        F[-1] = 1.0
        return np.interp(np.asarray(v, float), self.edges, F, left=0.0, right=1.0)

    @property
    def mean(self) -> float:
        """Mean wind speed [m/s] (at the bin centres)."""
        return float(self.frequency @ self.wind_speed)

    def name(self) -> str:
        return f"histogram {Path(self.source).name} (mean {self.mean:.3g} m/s)"


def _column(header, base, path, line):
    hits = [k for k, h in enumerate(header) if h.split("[")[0].strip().lower() == base]
    if len(hits) > 1:
        raise InputError(f"the column {base!r} appears {len(hits)} times (columns {', '.join(str(k + 1) for k in hits)})",
                         str(path), line=line, field=base)
    return hits[0] if hits else None


def read_wind_histogram(path) -> WindHistogram:
    """The histogram of ``path`` (module notes).

    Raises
    ------
    InputError
        Naming the file, the line and the column: a missing file, no ``wind_speed`` column or neither or
        both of ``hours`` and ``frequency``, a cell that is not a finite number (or a negative one), a row
        with another number of cells than the header, wind speeds not increasing, fewer than two rows, or
        nothing but zeros.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"wind-speed histogram not found: {path}", "--histogram", field="histogram")
    lines = [(k + 1, s.strip()) for k, s in enumerate(path.read_text().splitlines())]
    lines = [(k, s) for k, s in lines if s and not s.startswith("#")]
    if not lines:
        raise InputError("the histogram is empty: expected a header wind_speed,hours (or frequency) and one row "
                         "per bin", str(path), field="histogram")
    hline, head = lines[0]
    header = [h.strip() for h in head.split(",")]
    iv = _column(header, "wind_speed", path, hline)
    ih, i_f = _column(header, "hours", path, hline), _column(header, "frequency", path, hline)
    if iv is None or (ih is None) == (i_f is None):
        raise InputError(f"the header needs a column wind_speed [m/s] and one of hours [h] or frequency [-]; it has "
                         f"{', '.join(header)}", str(path), line=hline, field="header")
    iw = ih if ih is not None else i_f
    wname = "hours" if ih is not None else "frequency"
    v, w = [], []
    for k, s in lines[1:]:
        cells = [c.strip() for c in s.split(",")]
        if len(cells) != len(header):
            raise InputError(f"{len(cells)} cells where the header has {len(header)} columns", str(path), line=k,
                             field=header[min(len(cells), len(header)) - 1] if cells else "row")
        for col, out, unit in ((iv, v, "m/s"), (iw, w, "h" if wname == "hours" else "-")):
            try:
                x = float(cells[col])
            except ValueError:
                x = float("nan")
            if not np.isfinite(x) or x < 0:
                raise InputError(f"column {col + 1} ({header[col]}): {cells[col]!r} is not a finite number >= 0 "
                                 f"[{unit}]", str(path), line=k, field=header[col])
            out.append(x)
    v, w = np.array(v), np.array(w)
    if v.size < 2:
        raise InputError(f"the histogram needs at least two bins, it has {v.size}", str(path), field="histogram")
    bad = np.flatnonzero(np.diff(v) <= 0)
    if bad.size:
        k = lines[1 + bad[0] + 1][0]
        raise InputError(f"column {iv + 1} ({header[iv]}): the bin centres must increase ({v[bad[0] + 1]:g} after "
                         f"{v[bad[0]]:g})", str(path), line=k, field=header[iv])
    if not w.sum() > 0:
        raise InputError(f"column {iw + 1} ({header[iw]}): every bin is zero", str(path), field=header[iw])
    return WindHistogram(v, w / w.sum(), str(path), float(w.sum()) if wname == "hours" else None)
