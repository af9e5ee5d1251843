"""Measurement tables: CSV reading with units, noise models, synthetic measurements.

A measurement table holds, per operating point k, the conditions u_k and the measured
outputs z_k of some model channels, optionally with their 1-σ noise.

CSV layout
----------
One header line, then one row per record. Columns (order free):

- conditions: ``wind_speed`` [m/s], ``rotor_speed`` [rpm], ``pitch`` [deg] (required);
  ``air_density`` [kg/m^3] (optional, default 1.225), ``yaw`` [deg] (optional, default 0);
- channels: ``power`` [W], ``thrust`` [N], ``torque`` [N m], ``root_flap_moment`` [N m],
  ``root_edge_moment`` [N m], and spanwise channels ``<q>@<r/R>`` with ``q`` in
  ``cn``, ``ct`` (force coefficients [-]) or ``fn``, ``ft`` (force per unit length [N/m]),
  e.g. ``cn@0.30`` is the normal-force coefficient at r/R = 0.30;
- noise: ``<channel>_sigma``, the 1-σ noise of that channel, in the same unit.

A header may give a unit in brackets, ``power [kW]``; it is converted to SI on load
(see :data:`UNITS`). Without brackets SI is assumed. Rows with the same conditions are
*repeated records*; :func:`noise_from_repeats` estimates the noise from them.

Lines starting with ``#`` are comments.
"""

from __future__ import annotations

import csv
import hashlib
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from calib.errors import InputError
from calib.types import CONDITION_FIELDS, OperatingConditions

REQUIRED_CONDITIONS = ("wind_speed", "rotor_speed", "pitch")
CONDITION_DEFAULTS = {"air_density": 1.225, "yaw": 0.0}

#: Accepted units per physical quantity: unit -> factor to SI.
UNITS: dict[str, dict[str, float]] = {
    "speed": {"m/s": 1.0, "km/h": 1.0 / 3.6},
    "rotor_speed": {"rpm": 1.0, "rad/s": 30.0 / np.pi},          # SI of the contract is rpm
    "angle": {"deg": 1.0, "rad": 180.0 / np.pi},                  # contract angles are in deg
    "density": {"kg/m^3": 1.0, "kg/m3": 1.0},
    "power": {"W": 1.0, "kW": 1e3, "MW": 1e6},
    "force": {"N": 1.0, "kN": 1e3, "MN": 1e6},
    "moment": {"N m": 1.0, "Nm": 1.0, "kN m": 1e3, "kNm": 1e3, "MN m": 1e6, "MNm": 1e6},
    "coefficient": {"-": 1.0, "1": 1.0},
    "force_per_length": {"N/m": 1.0, "kN/m": 1e3},
}

_FIXED_QUANTITY = {
    "wind_speed": "speed", "rotor_speed": "rotor_speed", "pitch": "angle", "yaw": "angle",
    "air_density": "density", "power": "power", "thrust": "force", "torque": "moment",
    "root_flap_moment": "moment", "root_edge_moment": "moment", "hub_flap_moment": "moment",
}
_SPANWISE = re.compile(r"^(cn|ct|fn|ft)@([0-9]*\.?[0-9]+)$")
_HEADER = re.compile(r"^\s*([^\[\]]+?)\s*(?:\[\s*([^\]]*?)\s*\])?\s*$")


def quantity_of(column: str) -> str | None:
    """Physical quantity of a column name (``None`` if unknown)."""
    base = column[:-6] if column.endswith("_sigma") else column
    if base in _FIXED_QUANTITY:
        return _FIXED_QUANTITY[base]
    m = _SPANWISE.match(base)
    if m:
        return "coefficient" if m.group(1) in ("cn", "ct") else "force_per_length"
    return None


def is_channel_name(name: str) -> bool:
    """True for a known output-channel name (hub loads or spanwise ``q@r/R``)."""
    return name not in CONDITION_FIELDS and quantity_of(name) is not None and not name.endswith("_sigma")


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
    """

    conditions: OperatingConditions
    channels: tuple[str, ...]
    values: np.ndarray
    sigma: np.ndarray | None = None
    source: str = "memory"
    sha256: str = ""
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "channels", tuple(self.channels))
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

    @property
    def n_points(self) -> int:
        return len(self.conditions)

    def channel(self, name: str) -> np.ndarray:
        """Values of one channel, shape (n_points,)."""
        if name not in self.channels:
            raise KeyError(f"no channel {name!r}; measured channels are: {', '.join(self.channels)}")
        return self.values[:, self.channels.index(name)]

    def select_channels(self, names: Sequence[str]) -> "Measurements":
        """A copy restricted to ``names`` (in that order)."""
        missing = [n for n in names if n not in self.channels]
        if missing:
            raise InputError(f"channel(s) {', '.join(missing)} not measured; measured channels are: "
                             f"{', '.join(self.channels)}", self.source, field=missing[0])
        idx = [self.channels.index(n) for n in names]
        return replace(self, channels=tuple(names), values=self.values[:, idx],
                       sigma=None if self.sigma is None else self.sigma[:, idx])

    def with_sigma(self, sigma) -> "Measurements":
        """A copy with noise ``sigma`` (scalar, (n_channels,) or (n_points, n_channels))."""
        s = np.broadcast_to(np.asarray(sigma, dtype=float), self.values.shape).copy()
        return replace(self, sigma=s)

    def write_csv(self, path: str | Path) -> Path:
        """Write the table as CSV in SI units (with ``_sigma`` columns when known)."""
        path = Path(path)
        cols = list(CONDITION_FIELDS) + list(self.channels)
        data = [getattr(self.conditions, f) for f in CONDITION_FIELDS] + list(self.values.T)
        if self.sigma is not None:
            cols += [f"{c}_sigma" for c in self.channels]
            data += list(self.sigma.T)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(cols)
            for row in np.column_stack(data):
                w.writerow([repr(float(x)) for x in row])
        return path


def _parse_header(name: str, path: str, line: int) -> tuple[str, str | None]:
    m = _HEADER.match(name)
    if not m:
        raise InputError(f"cannot read column header {name!r}; expected 'name' or 'name [unit]'",
                         path, line, field=name)
    return m.group(1).strip(), (m.group(2).strip() if m.group(2) is not None else None)


def _factor(column: str, unit: str | None, path: str, line: int) -> float:
    quantity = quantity_of(column)
    if quantity is None:
        return 1.0  # unknown columns are ignored by the loader
    if unit is None:
        return 1.0
    table = UNITS[quantity]
    if unit not in table:
        raise InputError(f"unknown unit [{unit}] for {quantity}; accepted units: "
                         f"{', '.join(table)}", path, line, field=column)
    return table[unit]


def read_measurements(path: str | Path, channels: Sequence[str] | None = None) -> Measurements:
    """Read a measurement table from CSV (see the module docstring for the layout).

    Parameters
    ----------
    path : str or Path
        CSV file.
    channels : sequence of str, optional
        Channels to keep (default: every known channel column present).

    Returns
    -------
    Measurements
        Values in SI units; ``sigma`` set when every kept channel has a ``_sigma`` column.

    Raises
    ------
    InputError
        Empty file, missing required column, unknown unit, NaN or non-numeric cell
        (row and column named), σ <= 0, requested channel absent.
    """
    path = Path(path)
    src = str(path)
    if not path.is_file():
        raise InputError("file not found", src)
    with open(path, newline="") as f:
        lines = [(i + 1, ln) for i, ln in enumerate(f.read().splitlines())
                 if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise InputError("empty file: expected a header line and at least one data row", src)
    header_line, header = lines[0]
    names_units = [_parse_header(h, src, header_line) for h in next(csv.reader([header]))]
    names = [n for n, _ in names_units]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise InputError(f"duplicate column(s) {', '.join(dupes)}", src, header_line, field=dupes[0])
    for req in REQUIRED_CONDITIONS:
        if req not in names:
            raise InputError(f"missing required column '{req}'; columns present: {', '.join(names)}",
                             src, header_line, field=req)
    if len(lines) < 2:
        raise InputError("no data rows after the header", src, header_line)
    factors = [_factor(n, u, src, header_line) for n, u in names_units]
    rows = []
    for line_no, text in lines[1:]:
        cells = next(csv.reader([text]))
        if len(cells) != len(names):
            raise InputError(f"row has {len(cells)} cells, header has {len(names)}", src, line_no)
        row = []
        for cell, name in zip(cells, names):
            try:
                x = float(cell)
            except ValueError:
                raise InputError(f"not a number: {cell.strip()!r}", src, line_no, field=name) from None
            if not np.isfinite(x):
                raise InputError(f"value is {cell.strip()!r}; every cell must be a finite number",
                                 src, line_no, field=name)
            row.append(x)
        rows.append((line_no, row))
    data = np.array([r for _, r in rows], dtype=float) * np.array(factors)
    col = {n: data[:, i] for i, n in enumerate(names)}
    line_of = [ln for ln, _ in rows]
    cond = OperatingConditions(**{f: col.get(f, CONDITION_DEFAULTS.get(f)) for f in CONDITION_FIELDS})
    present = [n for n in names if is_channel_name(n)]
    if channels is None:
        channels = present
    channels = list(channels)
    for c in channels:
        if c not in present:
            raise InputError(f"channel '{c}' is not in the file; channel columns present: "
                             f"{', '.join(present) or '(none)'}", src, header_line, field=c)
    if not channels:
        raise InputError("no channel columns (e.g. power, thrust, cn@0.30)", src, header_line)
    values = np.column_stack([col[c] for c in channels])
    sigma = None
    sig_cols = [f"{c}_sigma" for c in channels]
    if any(s in col for s in sig_cols):
        missing = [s for s in sig_cols if s not in col]
        if missing:
            raise InputError(f"sigma given for some channels but not for {', '.join(missing)}",
                             src, header_line, field=missing[0])
        sigma = np.column_stack([col[s] for s in sig_cols])
        bad = np.argwhere(~(sigma > 0))
        if bad.size:
            k, c = bad[0]
            raise InputError(f"noise sigma must be > 0, got {sigma[k, c]!r}", src, line_of[k],
                             field=sig_cols[c])
    for f in REQUIRED_CONDITIONS:
        bad = np.flatnonzero(col[f] <= 0) if f != "pitch" else np.array([], int)
        if f == "wind_speed" and bad.size:
            raise InputError("wind speed must be > 0", src, line_of[bad[0]], field=f)
    return Measurements(cond, tuple(channels), values, sigma, source=src, sha256=sha256_of(path))


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
