"""Stated noise models for measurement tables without a 1-σ column.

``noise = "relative"`` in :class:`calib.calibration.settings.CalibrationSettings`: the 1-σ error of
every value of a channel is a stated fraction of that channel's RMS value over the table,

    σ_c = r_g · sqrt(mean_k y_kc²),

with r_g given per channel or per channel group (``cn`` for every ``cn@<r/R>`` channel,
``ct``, ``fn``, ``ft``; a channel's own entry wins over its group's). The RMS rather than
each value sets the scale so that a coefficient crossing zero (a chordwise force in stall)
does not get a vanishing σ. This is the model of a campaign that reports a few long-time
means per operating point: the random error of a 10-minute mean is small, and what the σ
has to carry is the systematic error of the transducers and of the model itself, which
scales with the size of the load.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from calib.errors import InputError


def group_of(channel: str) -> str:
    """The group a channel's relative σ may be given for: ``cn@0.30`` -> ``cn``, else the name."""
    return channel.split("@", 1)[0]


def relative_noise(values: np.ndarray, channels, fractions: Mapping[str, float], source: str = "settings",
                   field: str = "calibration.relative_sigma") -> np.ndarray:
    """1-σ noise of every value from stated fractions of each channel's RMS.

    Parameters
    ----------
    values : ndarray, shape (n_points, n_channels)
        Measured values [channel units].
    channels : sequence of str
        Channel names of the columns.
    fractions : mapping str -> float
        Relative 1-σ per channel or group [-].
    source, field : str
        Named in errors.

    Returns
    -------
    ndarray, shape (n_points, n_channels)
        σ [channel units].

    Raises
    ------
    InputError
        A channel without a fraction (neither its name nor its group given), a fraction
        <= 0, or a channel whose values are all zero.
    """
    values = np.asarray(values, float)
    sigma = np.empty_like(values)
    for j, c in enumerate(channels):
        r = fractions.get(c, fractions.get(group_of(c)))
        if r is None:
            raise InputError(f"no relative noise for channel {c!r}: give {field}.{group_of(c)} or "
                             f"{field}.\"{c}\" (a fraction of the channel's RMS, e.g. 0.03)", source,
                             field=f"{field}.{group_of(c)}")
        col = values[:, j]
        rms = float(np.sqrt(np.mean(col[np.isfinite(col)] ** 2))) if np.isfinite(col).any() else 0.0
        if not rms > 0:
            raise InputError(f"channel {c!r} is zero everywhere, so a σ relative to its size is zero", source,
                             field=f"{field}.{group_of(c)}")
        sigma[:, j] = float(r) * rms
    return sigma


def ml_scale(chi2: float, n_residuals: int, n_fitted: float) -> float:
    """Maximum-likelihood factor on a stated σ from a fit's χ²: k̂ = sqrt(χ² / (N − k)) [-].

    k̂ ≈ 1 says the stated noise model is consistent with the residuals; k̂ > 1 that the
    residuals are larger than stated (with N − k degrees of freedom, unbiased for k̂²).
    """
    dof = max(n_residuals - n_fitted, 1.0)
    return float(np.sqrt(chi2 / dof))


def initial_sigma(m, s) -> np.ndarray | None:
    """The noise 1-σ per point and channel the calibration starts from [channel units].

    From repeated records (``noise = "repeats"``), relative to the values (``relative``,
    ``relative_ml``, or ``ml`` with ``relative_sigma``), the settings' ``sigma`` or the table's
    ``_sigma`` columns; None for ``ml`` without them (the calibrator starts from the nominal residual).

    Parameters
    ----------
    m : Measurements
    s : CalibrationSettings

    Raises
    ------
    InputError
        ``sigma`` for an unmeasured channel, a σ ≤ 0, or ``noise = "known"`` without a σ for every
        channel (the message says where to state it).
    """
    shape = m.values.shape
    if s.noise == "repeats":
        from calib.measurements import noise_from_repeats

        return np.broadcast_to(noise_from_repeats(m), shape).copy()
    if s.noise in ("relative", "relative_ml") or (s.noise == "ml" and s.relative_sigma):
        # ml: the stated model is the start of the iteration (instead of the nominal residual)
        return relative_noise(m.values, m.channels, s.relative_sigma, m.source)
    if s.sigma:
        unknown = [c for c in s.sigma if c not in m.channels]
        if unknown:
            raise InputError(f"sigma given for unmeasured channel(s) {', '.join(unknown)}; measured: "
                             f"{', '.join(m.channels)}", "settings", field="sigma")
        missing = [c for c in m.channels if c not in s.sigma]
        if not missing:
            sig = np.array([float(s.sigma[c]) for c in m.channels])
            if np.any(~(sig > 0)):
                raise InputError("sigma must be > 0", "settings", field="sigma")
            return np.broadcast_to(sig, shape).copy()
        if m.sigma is None and s.noise == "known":
            raise InputError(f"no sigma for channel(s) {', '.join(missing)}", "settings", field="sigma")
    if m.sigma is not None:
        return m.sigma.copy()
    if s.noise == "known":
        raise InputError(
            "noise = 'known' needs the 1-σ noise of every channel, but the table has no _sigma columns ("
            + ", ".join(f"{c}_sigma" for c in m.channels) + ") and no sigma is set: set [calibration] sigma = {"
            + ", ".join(f"{c} = ..." for c in m.channels) + "} (absolute, SI units: W, N, N m), add the _sigma "
            "columns, or choose [calibration] noise = \"ml\" (from the residuals) or \"repeats\" (from "
            "repeated records); in Python: CalibrationSettings(sigma={...})", m.source, field="calibration.sigma")
    return None  # ml: from the nominal residual
