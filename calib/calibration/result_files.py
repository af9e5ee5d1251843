"""Reading a result back (:func:`load_result`): schema 3 as :meth:`CalibrationResult.save
<calib.calibration.result.CalibrationResult.save>` writes it, schema 2 (every field under its flat
name) through :func:`migrate_v2`; a missing file names the run's stage folders.
"""

from __future__ import annotations

import json
from dataclasses import fields
from pathlib import Path

import numpy as np

from calib.calibration.result import DICT_ARRAYS, SCHEMA_VERSION, CalibrationResult
from calib.calibration.result_parts import PARTS
from calib.errors import InputError

#: The part of each field of a schema-2 file (flat names; fixed: that schema does not change).
_V2_PARTS = {
    "estimate": ("p_nominal", "p_hat", "lower", "upper", "scale", "theta_hat", "status", "message", "history"),
    "identifiability": ("singular_values", "V", "sigma_theta", "retained", "sigma_bar", "correlation", "crb_std",
                        "observability", "verdicts", "confounding", "truncation", "fold_directions", "tightening"),
    "uncertainty": ("cov_p", "std_p", "cov_theta", "prior_std", "cov_frozen", "fit_scale", "aliasing_chi2",
                    "aliasing_note", "curvature", "prior_check", "gain", "cov_alias", "polar_bands"),
    "fit": ("measured", "sigma", "model_before", "model_after", "status_before", "status_after", "noise_sigma",
            "chi2_before", "chi2_after", "alpha_seen", "eta_seen", "multiple_roots", "failures"),
    "provenance": ("settings", "model_spec", "rotor_radius", "inputs", "versions", "wall_time", "checks"),
}


def migrate_v2(data: dict, arrays: dict) -> tuple[dict, dict]:
    """A schema-2 result (every field under its flat name in ``result.json`` and ``result.npz``)
    as schema 3 (each part's fields under the part's name; arrays as ``part.field``).

    Parameters
    ----------
    data : dict
        ``result.json`` of schema 2.
    arrays : dict of str to ndarray
        ``result.npz`` of schema 2.

    Returns
    -------
    data, arrays : dict, dict
        The same content in schema 3; names schema 2 did not know are dropped.
    """
    out = {k: data[k] for k in ("parameters", "channels", "channel_units", "name") if k in data}
    out["schema_version"] = SCHEMA_VERSION
    moved = {}
    for part, names in _V2_PARTS.items():
        out[part] = {k: data[k] for k in names if k in data}
        moved.update({f"{part}.{k}": arrays[k] for k in names if k in arrays})
    moved.update({k: v for k, v in arrays.items() if any(k.startswith(p) for _, p in DICT_ARRAYS.values())})
    return out, moved


def _result_files(path: Path, stem: str) -> tuple[Path, Path]:
    if path.is_dir():
        jpath, npath = path / f"{stem}.json", path / f"{stem}.npz"
    else:
        jpath, npath = path.with_suffix(".json"), path.with_suffix(".npz")
    for p in (jpath, npath):
        if not p.is_file():
            stages = sorted(d.name for d in path.iterdir() if (d / f"{stem}.json").is_file()) if path.is_dir() else []
            hint = (f"; this is a run's folder: give one of its stage folders, {', '.join(str(path / d) for d in stages)}"
                    if stages else "")
            raise InputError(f"result file not found (a folder holding {stem}.json and {stem}.npz, or their path)"
                             + hint, p)
    return jpath, npath


def load_result(path: str | Path, stem: str = "result") -> CalibrationResult:
    """Load a result written by :meth:`CalibrationResult.save` (schema 3, or schema 2 through
    :func:`migrate_v2`).

    Parameters
    ----------
    path : str or Path
        The output directory, or the ``.json`` / ``.npz`` file.

    Raises
    ------
    InputError
        A file missing, another schema version (named), or a field the result needs missing.
    """
    jpath, npath = _result_files(Path(path), stem)
    data = json.loads(jpath.read_text())
    with np.load(npath) as z:
        arrays = {k: z[k] for k in z.files}
    version = data.get("schema_version")
    if version == 2:
        data, arrays = migrate_v2(data, arrays)
    elif version != SCHEMA_VERSION:
        raise InputError(f"unsupported result schema {version!r}, expected {SCHEMA_VERSION} (or 2, migrated)",
                         jpath, field="schema_version")
    parts = {}
    for part, cls in PARTS.items():
        values = dict(data.get(part, {}))
        values.update({k[len(part) + 1:]: v for k, v in arrays.items() if k.startswith(part + ".")})
        for name, (owner, prefix) in DICT_ARRAYS.items():
            if owner == part:
                values[name] = {k[len(prefix):]: (v.item() if v.ndim == 0 and name == "truncation" else v)
                                for k, v in arrays.items() if k.startswith(prefix)}
        for name in ("retained", "multiple_roots"):
            if name in values:
                values[name] = np.asarray(values[name]).astype(bool)
        known = {f.name for f in fields(cls)}
        try:
            parts[part] = cls(**{k: v for k, v in values.items() if k in known})
        except TypeError as exc:      # a required field missing
            raise InputError(f"not a complete calibration result ({part}: {exc})", jpath) from None
    prefix = DICT_ARRAYS["conditions"][1]
    conditions = {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}
    own = {k: data[k] for k in ("parameters", "channels", "channel_units", "name") if k in data}
    return CalibrationResult(**own, conditions=conditions, **parts, json_path=jpath.resolve())
