"""The method of bins of IEC 61400-12-1: 10-minute records grouped by wind speed, one mean per bin.

:func:`method_of_bins` groups records into wind-speed bins of 0.5 m/s (centred on multiples of
0.5 m/s as the standard writes; ``align="left"`` puts the edges there instead, as OpenOA's
``power_curve.IEC`` does) and gives per bin the count N, the mean wind speed, the mean power,
the standard deviation of the power and the standard error of the mean power σ/√N, and the
bin's scatter in the conditions (the standard deviation, across the bin's records, of each
condition's mean, and the mean of the records' own 10-minute standard deviations where the export
gives them).

References
----------
IEC 61400-12-1:2017, method of bins (power curve and its category A uncertainty s = σ/√N).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib.errors import InputError


@dataclass(frozen=True)
class PowerCurveBins:
    """Bins with at least one record, in wind-speed order (arrays of shape (n_bins,)).

    Attributes
    ----------
    index : ndarray of int
        Bin number k: the bin is [offset + k width, offset + (k + 1) width).
    lower, upper : ndarray
        Bin edges [m/s].
    n : ndarray of int
        Records in the bin.
    wind_speed : ndarray
        Mean wind speed of the bin's records [m/s].
    power : ndarray
        Mean power [W].
    power_std : ndarray
        Standard deviation of the records' power [W] (ddof=1; NaN for N = 1).
    power_sigma : ndarray
        Standard error of the mean power σ/√N [W] (category A uncertainty of the bin).
    conditions : dict
        Name -> dict of ``mean``, ``std`` (across the bin's records, ddof=1) and, where the
        records carry their own 10-minute standard deviation, ``within_std`` (its mean).
    width, offset : float
        Bin width and the edge offset [m/s].
    """

    index: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    n: np.ndarray
    wind_speed: np.ndarray
    power: np.ndarray
    power_std: np.ndarray
    power_sigma: np.ndarray
    conditions: dict = field(default_factory=dict)
    width: float = 0.5
    offset: float = -0.25

    @property
    def centre(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)


def _std(x: np.ndarray) -> float:
    return float(np.std(x, ddof=1)) if x.size > 1 else np.nan


def method_of_bins(wind_speed, power, *, conditions: dict | None = None, within_std: dict | None = None,
                   width: float = 0.5, align: str = "iec") -> PowerCurveBins:
    """Bin 10-minute records by wind speed (see the module docstring).

    Parameters
    ----------
    wind_speed : array_like (n_records,)
        Mean wind speed [m/s] (normalized to the reference density where that applies).
    power : array_like (n_records,)
        Mean power [W].
    conditions : dict, optional
        Name -> array (n_records,) of further means to average and scatter per bin
        (``pitch`` [deg], ``rotor_speed`` [rpm], ``air_density`` [kg/m^3] ...).
    within_std : dict, optional
        Name -> array (n_records,) of the records' own 10-minute standard deviations
        (``wind_speed`` from ``Ws_std`` ...), averaged per bin.
    width : float
        Bin width [m/s] (0.5 in the standard).
    align : {"iec", "left"}
        ``"iec"``: bins centred on multiples of ``width``; ``"left"``: edges on multiples (OpenOA).

    Returns
    -------
    PowerCurveBins
        Records with a non-finite wind speed or power are in no bin.
    """
    if align not in ("iec", "left"):
        raise InputError(f"align must be 'iec' or 'left', got {align!r}", field="align")
    if not width > 0:
        raise InputError(f"width must be > 0 [m/s], got {width!r}", field="width")
    ws, p = np.asarray(wind_speed, float), np.asarray(power, float)
    offset = -0.5 * width if align == "iec" else 0.0
    ok = np.isfinite(ws) & np.isfinite(p)
    k = np.floor((ws - offset) / width)
    ks = np.unique(k[ok]).astype(int)
    conditions = {"wind_speed": ws, **(conditions or {})}
    rows = {name: {"mean": [], "std": []} for name in conditions}
    for name in within_std or {}:
        rows.setdefault(name, {"mean": [], "std": []})["within_std"] = []
    n, pm, ps = [], [], []
    for b in ks:
        sel = ok & (k == b)
        n.append(int(sel.sum()))
        pm.append(float(np.mean(p[sel])))
        ps.append(_std(p[sel]))
        for name, v in conditions.items():
            x = np.asarray(v, float)[sel]
            x = x[np.isfinite(x)]
            rows[name]["mean"].append(float(np.mean(x)) if x.size else np.nan)
            rows[name]["std"].append(_std(x))
        for name, v in (within_std or {}).items():
            x = np.asarray(v, float)[sel]
            x = x[np.isfinite(x)]
            rows[name]["within_std"].append(float(np.mean(x)) if x.size else np.nan)
    n_arr = np.array(n, int)
    ps_arr = np.array(ps, float)
    cond = {name: {s: np.array(v, float) for s, v in d.items() if v or ks.size == 0} for name, d in rows.items()}
    return PowerCurveBins(ks, offset + ks * width, offset + (ks + 1) * width, n_arr,
                          cond["wind_speed"]["mean"], np.array(pm, float), ps_arr, ps_arr / np.sqrt(n_arr),
                          {k_: v for k_, v in cond.items() if k_ != "wind_speed" or "within_std" in v} | {
                              "wind_speed": cond["wind_speed"]}, width, offset)


def bin_index(wind_speed, bins: PowerCurveBins) -> np.ndarray:
    """Row of ``bins`` each wind speed falls in (-1: a bin without records, or not finite)."""
    ws = np.asarray(wind_speed, float)
    with np.errstate(invalid="ignore"):
        k = np.floor((ws - bins.offset) / bins.width)
    row = {int(b): i for i, b in enumerate(bins.index)}
    return np.array([row.get(int(x), -1) if np.isfinite(x) else -1 for x in k], int)
