"""Measurements in the contract's units: names, units and the measurement table of a campaign.

:class:`Measurements` holds the operating conditions, the measured channels (SI units of the
ForwardModel contract), their 1-σ where stated, and what was done on reading (``notes``). The
names and units a file may use (:data:`~calib.measurements.units.UNITS`,
:func:`~calib.measurements.units.quantity_of`) are :mod:`calib.measurements.units`; reading
files is :mod:`calib.measurements.reader`. Also: channel checks against a model, groups of
repeated conditions, noise from repeats or by maximum likelihood, and synthetic measurements
from a model (:func:`synthesize`).
"""

from __future__ import annotations

import csv
import hashlib
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from calib.errors import InputError
from calib.measurements.units import quantity_of, si_unit
from calib.types import CONDITION_FIELDS, OperatingConditions

def sha256_of(path: str | Path) -> str:
    """SHA-256 hex digest of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 16), b""):
            h.update(chunk)
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class Measurements:
    """Measured outputs at a batch of operating points.

    Attributes
    ----------
    conditions : OperatingConditions
        n_points operating conditions.
    channels : tuple of str
        Names of the measured channels, length n_channels.
    values : ndarray, shape (n_points, n_channels)
        Measured values in SI units of the channels.
    sigma : ndarray, shape (n_points, n_channels), or None
        1-σ noise of each value (same units), when known.
    source : str
        File it came from, or a description (``"synthetic"``).
    sha256 : str
        SHA-256 of the file (empty for in-memory data).
    metadata : dict
        Free-form; :func:`read_measurements` stores ``units`` (column -> unit as declared in
        the header or the units row, in :data:`UNITS` spelling, ``None`` where none was given),
        ``delimiter``, ``decimal_comma``, ``units_row`` (its line, or ``None``), ``format``
        (``"csv"`` or ``"openfast"``), ``lines`` (file line of each point; of the first averaged
        row for an averaged time series) and, for OpenFAST output, ``openfast_channels`` (calib
        name -> OpenFAST name) and, when averaged, ``time_window`` [s] and ``time_rows``.
    notes : tuple of str
        What the reader did that a user should know (delimiter detected, columns
        ignored, rows dropped ...), one sentence each.
    condition_sigma : dict str -> ndarray, optional
        1-σ of the measured conditions per point, shape (n_points,) each, from the table's
        ``wind_speed_sigma`` [m/s], ``rotor_speed_sigma`` [rpm], ``pitch_sigma`` [deg] and
        ``air_density_sigma`` [kg/m^3] columns (those given), >= 0; read by the errors-in-variables estimator
        (:mod:`calib.calibration.errors_in_variables`).
    """

    conditions: OperatingConditions
    channels: tuple[str, ...]
    values: np.ndarray
    sigma: np.ndarray | None = None
    source: str = "memory"
    sha256: str = ""
    metadata: dict = field(default_factory=dict)
    notes: tuple[str, ...] = ()
    condition_sigma: dict | None = None

    def __repr__(self) -> str:
        """A short summary (``values``, ``sigma`` and ``conditions`` hold the arrays)."""
        v = self.conditions.wind_speed
        span = f", wind {v.min():.3g}–{v.max():.3g} m/s" if v.size else ""
        noise = "with σ" if self.sigma is not None else "no σ"
        return (f"Measurements({len(v)} points × {len(self.channels)} channels ({', '.join(self.channels)}){span}, "
                f"{noise}, from {self.source!r})")

    def __post_init__(self):
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "channels", tuple(self.channels))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        if v.shape != (len(self.conditions), len(self.channels)):
            raise InputError(f"values have shape {v.shape}, expected "
                             f"({len(self.conditions)}, {len(self.channels)})", self.source)
        if self.sigma is not None:
            s = np.broadcast_to(np.asarray(self.sigma, dtype=float), v.shape).copy()
            bad = np.argwhere(~(s > 0))
            if bad.size:
                k, c = bad[0]
                raise InputError(f"noise sigma must be > 0, got {s[k, c]!r} (row {k + 1})",
                                 self.source, field=f"{self.channels[c]}_sigma")
            object.__setattr__(self, "sigma", s)
        if self.condition_sigma is not None:
            cs = {}
            for name, value in self.condition_sigma.items():
                a = np.broadcast_to(np.asarray(value, dtype=float), (len(self.conditions),)).copy()
                bad = np.flatnonzero(~(a >= 0))
                if bad.size:
                    raise InputError(f"condition sigma must be >= 0, got {a[bad[0]]!r} (row {bad[0] + 1})",
                                     self.source, field=f"{name}_sigma")
                cs[name] = a
            object.__setattr__(self, "condition_sigma", cs)

    @property
    def n_points(self) -> int:
        return len(self.conditions)

    def channel(self, name: str) -> np.ndarray:
        """Values of one channel, shape (n_points,)."""
        if name not in self.channels:
            raise KeyError(f"no channel {name!r}; measured channels are: {', '.join(self.channels)}")
        return self.values[:, self.channels.index(name)]

    @classmethod
    def from_dataframe(cls, df, *args, **kwargs):
        """Refused with the new name: a DataFrame is read by :func:`calib.measurements.read_dataframe`
        (beside :func:`calib.measurements.read_measurements` for files)."""
        raise InputError("Measurements.from_dataframe(df, ...) is now calib.measurements.read_dataframe(df, ...), "
                         "with the same arguments", "Measurements.from_dataframe")

    def select_channels(self, names: Sequence[str]) -> "Measurements":
        """A copy restricted to ``names`` (in that order); notes and metadata are kept."""
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise InputError(f"channel(s) {', '.join(missing)} not measured; measured channels are: "
                             f"{', '.join(self.channels)}", self.source, field=missing[0])
        idx = [self.channels.index(n) for n in names]
        return replace(self, channels=tuple(names), values=self.values[:, idx],
                       sigma=None if self.sigma is None else self.sigma[:, idx])

    def select_points(self, index) -> "Measurements":
        """A copy with the points at ``index`` (any numpy index): conditions, values, σ and the
        conditions' σ; notes and metadata are kept."""
        sub = {k: v[index] for k, v in self.condition_sigma.items()} if self.condition_sigma else None
        return replace(self, conditions=self.conditions.subset(index), values=self.values[index],
                       sigma=None if self.sigma is None else self.sigma[index], condition_sigma=sub)

    def with_sigma(self, sigma) -> "Measurements":
        """A copy with noise ``sigma`` (scalar, (n_channels,) or (n_points, n_channels))."""
        s = np.broadcast_to(np.asarray(sigma, dtype=float), self.values.shape).copy()
        return replace(self, sigma=s)

    def write_csv(self, path: str | Path) -> Path:
        """Write the table as CSV in SI units, each column header with its unit.

        ``_sigma`` columns are written when the noise is known, and the conditions' σ columns
        (``wind_speed_sigma`` ...) when given. The source and the
        :attr:`notes` are written as ``#`` comment lines above the header (reading the
        file back gives fresh notes about the written file). The file is written to a
        temporary name and renamed, so an interruption never leaves a truncated table.
        """
        path = Path(path)

        def header(name: str) -> str:
            q = quantity_of(name)
            return f"{name} [{si_unit(q)}]" if q is not None else name

        cols = list(CONDITION_FIELDS) + list(self.channels)
        data = [getattr(self.conditions, f) for f in CONDITION_FIELDS] + list(self.values.T)
        if self.sigma is not None:
            cols += [f"{c}_sigma" for c in self.channels]
            data += list(self.sigma.T)
        for name, sig in (self.condition_sigma or {}).items():   # the conditions' σ, for errors in variables
            cols.append(f"{name}_sigma")
            data.append(sig)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        try:
            with open(tmp, "w", newline="", encoding="utf-8") as f:
                f.write(f"# written by calib from {self.source}\n")
                for note in self.notes:
                    f.write("# note: " + " ".join(note.splitlines()) + "\n")
                w = csv.writer(f)
                w.writerow([header(c) for c in cols])
                for row in np.column_stack(data):
                    w.writerow([repr(float(x)) for x in row])
                f.flush()
                os.fsync(f.fileno())  # on disk before the rename makes it the file (a crash keeps the old one)
            os.replace(tmp, path)
        finally:
            if tmp.exists():
                tmp.unlink()
        return path


# ----------------------------------------------------------------------------- reading
def check_channels(measurements: Measurements, model_channels: Sequence[str]) -> None:
    """Raise :class:`InputError` if a measured channel is not an output of the model."""
    missing = [c for c in measurements.channels if c not in model_channels]
    if missing:
        raise InputError(f"channel(s) {', '.join(missing)} not provided by the model; the model's "
                         f"channels are: {', '.join(model_channels)}", measurements.source,
                         field=missing[0])


# ----------------------------------------------------------------------------- noise
def condition_groups(conditions: OperatingConditions, decimals: int = 6) -> np.ndarray:
    """Group index of each point; points with identical (rounded) conditions share a group.

    Returns
    -------
    ndarray of int, shape (n_points,)
    """
    key = np.column_stack([np.round(getattr(conditions, f), decimals) for f in CONDITION_FIELDS])
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    return inverse.reshape(-1)


def noise_from_repeats(measurements: Measurements) -> np.ndarray:
    """Per-channel 1-σ noise pooled over repeated records at the same conditions.

    Notes
    -----
    The pooled variance is σ_c² = Σ_g Σ_{k∈g} (z_kc − z̄_gc)² / (N − G), with G groups of
    repeated conditions and N records (unbiased, one mean per group).

    Returns
    -------
    ndarray, shape (n_channels,)

    Raises
    ------
    InputError
        If no condition is repeated.
    """
    groups = condition_groups(measurements.conditions)
    n_groups = groups.max() + 1
    dof = measurements.n_points - n_groups
    if dof <= 0:
        raise InputError("noise 'from repeats' needs repeated records at the same conditions; "
                         "every row has different conditions", measurements.source)
    z = measurements.values
    means = np.zeros((n_groups, z.shape[1]))
    np.add.at(means, groups, z)
    means /= np.bincount(groups, minlength=n_groups)[:, None]
    var = ((z - means[groups]) ** 2).sum(axis=0) / dof
    if np.any(var <= 0):
        c = int(np.flatnonzero(var <= 0)[0])
        raise InputError("repeated records are identical: cannot estimate the noise",
                         measurements.source, field=measurements.channels[c])
    return np.sqrt(var)


def ml_noise(residuals: np.ndarray, mask: np.ndarray | None = None, floor: float = 1e-12) -> np.ndarray:
    """Maximum-likelihood per-channel noise from residuals: σ_c² = mean_k r_kc².

    Parameters
    ----------
    residuals : ndarray, shape (n_points, n_channels)
    mask : ndarray of bool, shape (n_points,), optional
        Points to use (e.g. converged ones).

    Notes
    -----
    For a diagonal R this is the closed-form update R = (1/N) Σ r_k r_kᵀ of
    Bottasso et al. (2014), restricted to the diagonal.
    """
    r = residuals if mask is None else residuals[mask]
    return np.sqrt(np.maximum(np.mean(r ** 2, axis=0), floor))


# ----------------------------------------------------------------------------- synthetic
def synthesize(model, p_true, conditions: OperatingConditions, sigma: Mapping[str, float] | None = None,
               relative_sigma: Mapping[str, float] | None = None, channels: Sequence[str] | None = None,
               seed: int = 0, repeats: int = 1, source: str = "synthetic") -> Measurements:
    """Synthetic measurements from a (truth) forward model plus Gaussian noise.

    Parameters
    ----------
    model : ForwardModel
        Truth model.
    p_true : array_like, shape (n_params,)
        Truth parameter vector of ``model``.
    conditions : OperatingConditions
    sigma : mapping channel -> float, optional
        Absolute 1-σ noise per channel [channel unit].
    relative_sigma : mapping channel -> float, optional
        Noise as a fraction of the channel's RMS truth value over all points [-].
    channels : sequence of str, optional
        Channels to keep (default: all of the model).
    seed : int
        Seed of the noise generator.
    repeats : int
        Records per condition (repeated records allow :func:`noise_from_repeats`).

    Raises
    ------
    ModelError
        If the truth model fails at any point (synthetic data must be complete).
    """
    from calib.errors import ModelError

    names = [c.name for c in model.channels]
    channels = list(channels or names)
    ev = model.evaluate(np.asarray(p_true, float), conditions)
    if ev.n_failed:
        raise ModelError(f"truth model failed: {ev.failure_summary()}")
    idx = [names.index(c) for c in channels]
    y = ev.values[:, idx]
    s = np.zeros(len(channels))
    for i, c in enumerate(channels):
        if sigma and c in sigma:
            s[i] = float(sigma[c])
        elif relative_sigma and c in relative_sigma:
            s[i] = float(relative_sigma[c]) * float(np.sqrt(np.mean(y[:, i] ** 2)))
        else:
            raise InputError(f"no noise level given for channel '{c}'", source, field=c)
    rng = np.random.default_rng(seed)
    if repeats > 1:
        rep = np.repeat(np.arange(len(conditions)), repeats)
        conditions = conditions.subset(rep)
        y = y[rep]
    z = y + rng.standard_normal(y.shape) * s
    return Measurements(conditions, tuple(channels), z, np.broadcast_to(s, z.shape).copy(),
                        source=source, metadata={"truth": np.asarray(p_true, float).tolist(), "seed": seed})
