"""Synthetic SCADA-like campaigns with errors in the conditions, for the errors-in-variables
validation (``benchmarks/bench_eiv.py``), its tests and the field workflow's data.

A campaign is n 10-minute records of a variable-speed, pitch-regulated rotor on the native BEM:
true hub wind speeds drawn uniformly over a range, the rotor speed from the optimal tip-speed
ratio clipped to the rotor's speed range, the pitch 0 below rated and rising above it, the air
density from a temperature and a pressure (ideal gas, dry air: ρ = p / (R_d T), R_d = 287.05
J/(kg K); IEC 61400-12-1 (2017) eq. 12 without the humidity term). The outputs are the model's at
the true conditions plus Gaussian output noise; the *measured* conditions carry a nacelle
anemometer error V_m = s_V V (1 + ε_V), ε_V ~ N(0, r_V²), and a pitch reading β_m = β − Δβ + ε_β,
ε_β ~ N(0, σ_β²) (the model adds its ``pitch_offset`` Δβ to the measured pitch).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.measurements import Measurements
from calib.types import OperatingConditions

R_DRY_AIR = 287.05
"""Gas constant of dry air [J/(kg K)] (IEC 61400-12-1:2017, eq. 12)."""


@dataclass(frozen=True)
class CampaignSpec:
    """What a synthetic SCADA-like campaign draws.

    Attributes
    ----------
    n_records : int
    wind_range : tuple of float
        True hub wind speeds drawn uniformly in it [m/s].
    tsr : float
        Tip-speed ratio of the speed controller below rated [-].
    rotor_speed_range : tuple of float
        [rpm].
    rated_wind : float
        Wind speed above which the pitch rises [m/s].
    pitch_slope : float
        Pitch above rated: slope·(V − V_rated)^0.75 [deg / (m/s)^0.75].
    anemometer_scale : float
        s_V: the nacelle anemometer reads s_V times the true wind speed [-].
    wind_scatter : float
        r_V: relative 1-σ of the anemometer per record [-].
    pitch_offset : float
        Δβ [deg]: the pitch reading is Δβ below the blades' true pitch.
    pitch_scatter : float
        σ_β [deg] per record.
    output_sigma : dict channel -> float
        Output 1-σ as a fraction of each channel's RMS over the campaign [-].
    """

    n_records: int = 120
    wind_range: tuple = (5.0, 16.0)
    tsr: float = 7.5
    rotor_speed_range: tuple = (6.9, 12.1)
    rated_wind: float = 11.4
    pitch_slope: float = 3.0
    anemometer_scale: float = 0.97
    wind_scatter: float = 0.03
    pitch_offset: float = 0.5
    pitch_scatter: float = 0.2
    output_sigma: tuple = (("power", 0.01), ("thrust", 0.02), ("root_flap_moment", 0.02))


def true_conditions(spec: CampaignSpec, radius: float, rng: np.random.Generator) -> OperatingConditions:
    """The records' true conditions (module docstring) for a rotor of ``radius`` [m]."""
    v = rng.uniform(*spec.wind_range, spec.n_records)
    omega = np.clip(spec.tsr * v / radius * 30.0 / np.pi, *spec.rotor_speed_range)
    pitch = spec.pitch_slope * np.clip(v - spec.rated_wind, 0.0, None) ** 0.75
    temperature = rng.uniform(268.0, 298.0, spec.n_records)        # [K]
    pressure = rng.normal(101_325.0, 800.0, spec.n_records)         # [Pa]
    return OperatingConditions(v, omega, pitch, air_density=pressure / (R_DRY_AIR * temperature))


def synthesize_campaign(model, p_true: np.ndarray, spec: CampaignSpec, seed: int,
                        channels=None) -> tuple[Measurements, OperatingConditions]:
    """A campaign's measurements (measured conditions, noisy outputs, output σ, condition σ) and its
    true conditions.

    Parameters
    ----------
    model : ForwardModel
        The truth's model; ``p_true`` its parameters (with the model's own ``pitch_offset`` set to
        0 or absent: the offset is put into the measured pitch here).
    p_true : ndarray
    spec : CampaignSpec
    seed : int
    channels : sequence of str, optional
        Default: those of ``spec.output_sigma``.

    Returns
    -------
    Measurements
        ``condition_sigma``: ``wind_speed`` r_V × V_m [m/s], ``pitch`` σ_β [deg] per record.
    OperatingConditions
        The true conditions.
    """
    rng = np.random.default_rng(seed)
    radius = float(model.rotor_radius)
    true = true_conditions(spec, radius, rng)
    fractions = dict(spec.output_sigma)
    channels = tuple(channels or fractions)
    names = [c.name for c in model.channels]
    ev = model.evaluate(p_true, true)
    if not np.all(ev.ok):
        raise RuntimeError(f"the truth fails at {int(np.sum(~ev.ok))} record(s): {ev.failure_summary()}")
    y = ev.values[:, [names.index(c) for c in channels]]
    return campaign_from_truth(y, true, spec, rng, channels, f"synthetic seed {seed}"), true


def campaign_from_truth(y: np.ndarray, true: OperatingConditions, spec: CampaignSpec, rng: np.random.Generator,
                        channels, source: str) -> Measurements:
    """The measurements of records whose noise-free outputs ``y`` at the ``true`` conditions come from
    any truth (the native BEM in :func:`synthesize_campaign`, another code in the out-of-family
    campaign): output noise and the measured conditions of the module docstring, drawn from ``rng``
    after the true conditions (:func:`true_conditions`).

    Parameters
    ----------
    y : ndarray, shape (n_records, n_channels)
        Noise-free outputs [channel units], in the order of ``channels``.
    true : OperatingConditions
    spec : CampaignSpec
    rng : numpy.random.Generator
    channels : sequence of str
        Each channel's σ fraction is ``spec.output_sigma``'s.
    source : str
    """
    fractions = dict(spec.output_sigma)
    sigma = np.array([fractions[c] for c in channels]) * np.sqrt(np.mean(y ** 2, axis=0))
    z = y + sigma * rng.standard_normal(y.shape)
    v_m = spec.anemometer_scale * true.wind_speed * (1.0 + spec.wind_scatter * rng.standard_normal(len(true)))
    beta_m = true.pitch - spec.pitch_offset + spec.pitch_scatter * rng.standard_normal(len(true))
    measured = OperatingConditions(v_m, true.rotor_speed, beta_m, true.air_density)
    cond_sigma = {"wind_speed": spec.wind_scatter * v_m, "pitch": np.full(len(true), spec.pitch_scatter)}
    return Measurements(measured, tuple(channels), z, np.broadcast_to(sigma, z.shape).copy(), source=source,
                        condition_sigma=cond_sigma)
