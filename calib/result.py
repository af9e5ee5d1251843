"""The calibration result: one object that serializes to JSON + NPZ and loads back.

``result.json`` holds the settings, the scalar figures of merit, the verdicts, the
history, the input SHA-256 hashes and the package versions; ``result.npz`` holds every
array. Both are written atomically (temporary file, then rename).
"""

from __future__ import annotations

import json
import os
import platform
import tempfile
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.identifiability import NodeLayout, eigenshapes, node_layout
from calib.types import Parameter

SCHEMA_VERSION = 1


def package_versions() -> dict[str, str]:
    """Versions of Python and the numerical packages the result depends on."""
    import importlib.metadata as md

    out = {"python": platform.python_version()}
    for name in ("calib", "numpy", "scipy", "casadi", "matplotlib"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            out[name] = "unknown"
    return out


def _atomic_write(path: Path, writer) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        writer(tmp)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


_ARRAY_FIELDS = ("p_nominal", "p_hat", "lower", "upper", "scale", "cov_p", "std_p", "singular_values", "V",
                 "sigma_theta", "retained", "theta_hat", "cov_theta", "theta_nominal_linearization",
                 "correlation", "crb_std", "observability", "measured", "sigma", "model_before",
                 "model_after", "status_before", "status_after", "alpha_seen", "eta_seen", "noise_sigma")


@dataclass(eq=False)
class CalibrationResult:
    """Everything a calibration produced.

    Array attributes (shapes; n = n_params, m = n_points, c = n_channels, r = n_retained)
    -----------------------------------------------------------------------------------
    p_nominal, p_hat, lower, upper, scale : (n,)
        Nominal and estimated parameters, effective bounds and scales.
    cov_p, std_p : (n, n), (n,)
        Covariance / standard deviation of p̂ (truncated-SVD estimator: zero outside the
        retained subspace).
    singular_values, V, sigma_theta, retained : (n,), (n, n), (n,), (n,) bool
        SVD of the whitened scaled sensitivities at p̂ (DESIGN §5).
    theta_hat, cov_theta : (r,), (r, r)
        Retained θ = V_IDᵀ p̃ and their covariance [scale units].
    correlation, crb_std : (n, n), (n,)
        Cramér–Rao correlation matrix and standard deviations of the full nodal problem.
    observability : (n,)
        Fraction of each scaled parameter inside the retained subspace.
    measured, sigma, model_before, model_after : (m, c)
    status_before, status_after : (m,) int
    alpha_seen, eta_seen : (k,)
        (α, η) the converged operating points see at p̂ (empty if the model does not report it).
    noise_sigma : (c,)
        Per-channel noise used in the final estimate.
    """

    parameters: list[dict]
    channels: list[str]
    channel_units: list[str]
    conditions: dict[str, np.ndarray]
    settings: dict
    p_nominal: np.ndarray
    p_hat: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    cov_p: np.ndarray
    std_p: np.ndarray
    singular_values: np.ndarray
    V: np.ndarray
    sigma_theta: np.ndarray
    retained: np.ndarray
    theta_hat: np.ndarray
    cov_theta: np.ndarray
    theta_nominal_linearization: np.ndarray
    correlation: np.ndarray
    crb_std: np.ndarray
    observability: np.ndarray
    measured: np.ndarray
    sigma: np.ndarray
    model_before: np.ndarray
    model_after: np.ndarray
    status_before: np.ndarray
    status_after: np.ndarray
    alpha_seen: np.ndarray
    eta_seen: np.ndarray
    noise_sigma: np.ndarray
    sigma_bar: float
    verdicts: list[dict]
    history: list[dict]
    status: str
    message: str
    failures: dict
    chi2_before: float
    chi2_after: float
    rotor_radius: float | None = None
    polar_bands: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    versions: dict = field(default_factory=package_versions)
    wall_time: float = 0.0
    name: str = "calibration"

    # ------------------------------------------------------------------ derived
    @property
    def n_params(self) -> int:
        return int(self.p_hat.size)

    @property
    def n_retained(self) -> int:
        return int(np.count_nonzero(self.retained))

    @property
    def n_points(self) -> int:
        return int(self.measured.shape[0])

    @property
    def dof(self) -> int:
        """Degrees of freedom of χ²: converged residuals minus retained parameters."""
        ok = self.status_after == 0
        return int(ok.sum() * len(self.channels) - self.n_retained)

    @property
    def parameter_objects(self) -> tuple[Parameter, ...]:
        keys = {f.name for f in fields(Parameter)}
        return tuple(Parameter(**{k: v for k, v in d.items() if k in keys}) for d in self.parameters)

    @property
    def layout(self) -> NodeLayout:
        return node_layout(self.parameter_objects)

    def verdict_counts(self) -> dict[str, int]:
        out = {"identified": 0, "poorly observable": 0, "at bound": 0}
        for v in self.verdicts:
            out[v["verdict"]] = out.get(v["verdict"], 0) + 1
        return out

    def rms(self, which: str = "after") -> dict[str, float]:
        """Per-channel RMS of the residual (converged points) [channel units]."""
        model = self.model_after if which == "after" else self.model_before
        status = self.status_after if which == "after" else self.status_before
        ok = status == 0
        return {c: float(np.sqrt(np.mean((self.measured[ok, i] - model[ok, i]) ** 2)))
                for i, c in enumerate(self.channels)}

    def tip_speed_ratio(self) -> np.ndarray | None:
        """λ = ΩR/V of each point [-] (None when the rotor radius is unknown)."""
        if not self.rotor_radius:
            return None
        return self.conditions["rotor_speed"] * np.pi / 30.0 * self.rotor_radius / self.conditions["wind_speed"]

    def eigenshapes(self, alpha_deg, eta, modes=None):
        """Lift and drag eigenshapes (n_modes, n_eta, n_alpha) of the given modes (default: retained)."""
        if modes is None:
            modes = np.flatnonzero(self.retained)
        return eigenshapes(self.V, self.layout, alpha_deg, eta, modes)

    def summary(self) -> str:
        """A few plain lines with the key numbers."""
        counts = self.verdict_counts()
        lines = [f"{self.name}: {self.status} ({self.message})",
                 f"  parameters {self.n_params}, retained {self.n_retained} (sigma_bar = {self.sigma_bar:g})",
                 f"  chi2/dof before {self.chi2_before / max(self.dof, 1):.3g}, after "
                 f"{self.chi2_after / max(self.dof, 1):.3g} (dof {self.dof})",
                 "  verdicts: " + ", ".join(f"{k} {v}" for k, v in counts.items()),
                 "  failed model points: " + ", ".join(f"{k} {v}" for k, v in self.failures.items())]
        rb, ra = self.rms("before"), self.rms("after")
        for c in self.channels:
            lines.append(f"  rms {c}: {rb[c]:.4g} -> {ra[c]:.4g}")
        return "\n".join(lines)

    # ------------------------------------------------------------------ i/o
    def to_json_dict(self) -> dict:
        scalars = {}
        for f in fields(self):
            if f.name in _ARRAY_FIELDS or f.name in ("conditions", "polar_bands"):
                continue
            scalars[f.name] = getattr(self, f.name)
        scalars["schema_version"] = SCHEMA_VERSION
        scalars["summary"] = {"n_params": self.n_params, "n_retained": self.n_retained, "dof": self.dof,
                              "chi2_per_dof_before": self.chi2_before / max(self.dof, 1),
                              "chi2_per_dof_after": self.chi2_after / max(self.dof, 1),
                              "rms_before": self.rms("before"), "rms_after": self.rms("after"),
                              "verdict_counts": self.verdict_counts()}
        return _jsonable(scalars)

    def save(self, out_dir: str | Path, stem: str = "result") -> tuple[Path, Path]:
        """Write ``<stem>.json`` and ``<stem>.npz`` into ``out_dir`` (atomically)."""
        out_dir = Path(out_dir)
        jpath, npath = out_dir / f"{stem}.json", out_dir / f"{stem}.npz"
        text = json.dumps(self.to_json_dict(), indent=1, allow_nan=True)
        _atomic_write(jpath, lambda tmp: Path(tmp).write_text(text))
        arrays = {k: np.asarray(getattr(self, k)) for k in _ARRAY_FIELDS}
        arrays.update({f"conditions__{k}": np.asarray(v) for k, v in self.conditions.items()})
        arrays.update({f"polar__{k}": np.asarray(v) for k, v in self.polar_bands.items()})

        def write_npz(tmp):
            with open(tmp, "wb") as f:
                np.savez_compressed(f, **arrays)

        _atomic_write(npath, write_npz)
        return jpath, npath


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.floating,)):
        return float(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    if isinstance(x, Path):
        return str(x)
    return x


def load_result(path: str | Path, stem: str = "result") -> CalibrationResult:
    """Load a result written by :meth:`CalibrationResult.save`.

    Parameters
    ----------
    path : str or Path
        The output directory, or the ``.json`` / ``.npz`` file.
    """
    path = Path(path)
    if path.is_dir():
        jpath, npath = path / f"{stem}.json", path / f"{stem}.npz"
    else:
        jpath, npath = path.with_suffix(".json"), path.with_suffix(".npz")
    for p in (jpath, npath):
        if not p.is_file():
            raise InputError("result file not found", p)
    data = json.loads(jpath.read_text())
    if data.get("schema_version") != SCHEMA_VERSION:
        raise InputError(f"unsupported result schema {data.get('schema_version')!r}, expected {SCHEMA_VERSION}",
                         jpath, field="schema_version")
    data.pop("schema_version")
    data.pop("summary", None)
    with np.load(npath) as z:
        arrays = {k: z[k] for k in z.files}
    kwargs = {k: arrays[k] for k in _ARRAY_FIELDS}
    kwargs["retained"] = kwargs["retained"].astype(bool)
    kwargs["conditions"] = {k.split("__", 1)[1]: v for k, v in arrays.items() if k.startswith("conditions__")}
    kwargs["polar_bands"] = {k.split("__", 1)[1]: v for k, v in arrays.items() if k.startswith("polar__")}
    names = {f.name for f in fields(CalibrationResult)}
    kwargs.update({k: v for k, v in data.items() if k in names})
    return CalibrationResult(**kwargs)
