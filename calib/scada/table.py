"""SCADA bins or records written as a calib measurement table (CSV, read by
:func:`calib.measurements.read_measurements`).

Columns: the conditions ``wind_speed`` [m/s], ``rotor_speed`` [rpm], ``pitch`` [deg] and, where
known, ``air_density`` [kg/m^3]; the channel ``power`` [W] with ``power_sigma``; and the
conditions' own σ (``wind_speed_sigma``, ``rotor_speed_sigma``, ``pitch_sigma``, and for records
``air_density_sigma`` from the temperature and pressure sensors' σ) for the errors-in-variables
estimators.

- bins: one row per bin with at least ``min_count`` records; ``power_sigma`` is σ/√N and a
  condition's σ is its scatter across the bin's records over √N (the uncertainty of the bin mean);
- records: one row per kept record; ``power_sigma`` and a condition's σ are the scatter across the
  records of the record's bin (what one record may differ from another at that wind speed).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.scada.bins import PowerCurveBins, bin_index

CONDITIONS = ("wind_speed", "rotor_speed", "pitch")


def _columns(source: str, means: dict, sigmas: dict, power, power_sigma, fill: dict | None):
    cols, notes = {}, []
    for name in CONDITIONS:
        if name in means:
            cols[name] = means[name]
        elif fill and name in fill:
            cols[name] = np.full(len(power), float(fill[name]))
            notes.append(f"{name} not measured: {float(fill[name]):g} in every row (fill=)")
        else:
            raise InputError(f"the export has no mean {name}, which a calib measurement table needs; give it in "
                             f"fill={{'{name}': value}} if the turbine held it constant", source, field=name)
    if "air_density" in means:
        cols["air_density"] = means["air_density"]
    cols["power"], cols["power_sigma"] = power, power_sigma
    for name in CONDITIONS:
        if name in sigmas:
            cols[f"{name}_sigma"] = sigmas[name]
    if "air_density" in means and "air_density" in sigmas:
        cols["air_density_sigma"] = np.broadcast_to(np.asarray(sigmas["air_density"], float), power.shape)
    return cols, notes


def _write(path: Path, cols: dict, comments: list[str], said: list | None = None) -> Path:
    """Write the rows in operation with finite values and σ > 0; the rows left out are counted in the
    file's comments and appended to ``said`` (for the console)."""
    path = Path(path)
    finite = np.all([np.isfinite(v) for v in cols.values()], axis=0) & (cols["power_sigma"] > 0)
    # a steady operating point of the rotor model: wind and power > 0 (a parked, idling or motoring rotor
    # below cut-in is in the IEC power curve's bins, never a calibration point; read_measurements refuses
    # a wind speed <= 0)
    with np.errstate(invalid="ignore"):
        operating = (cols["wind_speed"] > 0) & (cols["power"] > 0)
    keep = finite & operating
    left = []
    if np.any(finite & ~operating):
        left.append(f"{int((finite & ~operating).sum())} rows not in operation (wind speed or power <= 0: parked, "
                    "idling or below cut-in) not written")
    if not finite.all():
        left.append(f"{int((~finite).sum())} rows without a finite value or with sigma 0 not written")
    if said is not None:
        said += left
    with path.open("w") as fh:
        for c in [*comments, *left]:
            fh.write(f"# {c}\n")
        fh.write(",".join(cols) + "\n")
        for i in np.flatnonzero(keep):
            fh.write(",".join(f"{cols[c][i]:.10g}" for c in cols) + "\n")
    return path


def write_bins_table(bins: PowerCurveBins, path, *, min_count: int = 3, fill: dict | None = None,
                     source: str = "bins", comments=(), said: list | None = None) -> Path:
    """Write the bins with ``min_count`` or more records as a measurement table (module docstring); bins
    not in operation (mean wind speed or power <= 0) are left out, counted in the file's comments and in
    ``said``.

    Raises
    ------
    InputError
        A required condition (rotor speed, pitch) neither binned nor in ``fill``.
    """
    sel = bins.n >= min_count
    root_n = np.sqrt(bins.n[sel])
    means = {"wind_speed": bins.wind_speed[sel]}
    sigmas = {"wind_speed": bins.conditions["wind_speed"]["std"][sel] / root_n}
    for name, d in bins.conditions.items():
        if name != "wind_speed":
            means[name] = d["mean"][sel]
            if name in CONDITIONS:
                sigmas[name] = d["std"][sel] / root_n
    cols, notes = _columns(source, means, sigmas, bins.power[sel], bins.power_sigma[sel], fill)
    return _write(path, cols, list(comments) + notes + [f"method of bins, width {bins.width:g} m/s, bins with "
                                                        f"N >= {min_count}: {int(sel.sum())}"], said)


def write_records_table(means: dict, power, bins: PowerCurveBins, path, *, fill: dict | None = None,
                        source: str = "records", comments=(), density_sigma=None, said: list | None = None) -> Path:
    """Write records (``means``: condition -> array, ``power`` [W]) as a measurement table, with σ from
    the scatter of each record's bin in ``bins`` (module docstring); records in bins of one record
    are left out and counted in a comment. ``density_sigma`` [kg/m^3] (per record or one value): the
    air density's own 1-σ (:func:`calib.scada.density.air_density_sigma`), written as
    ``air_density_sigma`` beside a measured or computed ``air_density``. Records not in operation (wind
    speed or power <= 0) are left out, counted in the file's comments and in ``said``."""
    k = bin_index(means["wind_speed"], bins)
    ok = k >= 0
    take = np.clip(k, 0, None)

    def scatter(v):
        return np.where(ok, v[take], np.nan)

    sigmas = {name: scatter(bins.conditions[name]["std"]) for name in CONDITIONS if name in bins.conditions}
    if density_sigma is not None:
        sigmas["air_density"] = density_sigma
    cols, notes = _columns(source, means, sigmas, np.asarray(power, float), scatter(bins.power_std), fill)
    return _write(path, cols, list(comments) + notes + [f"records, sigma = scatter of the record's {bins.width:g} "
                                                        "m/s bin"], said)
