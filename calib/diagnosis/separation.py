"""What measurement would tell two candidate effects apart, when the data cannot (docs/theory.md, Diagnosis).

When two candidates of different physics explain a campaign about equally (an ``ambiguous``
verdict of :mod:`calib.diagnosis.core`), both fitted models agree where the campaign measured.
Where they disagree is found by asking them: both are evaluated on *probes*, operating
points around and beyond the measured envelope (other tip-speed ratios, pitch angles and
wind speeds at the same tip-speed ratio, which change only the Reynolds number) and channels
the campaign did not measure (spanwise blade loads, where the model has them). The probe
where their predictions differ most against the noise and model-form tolerance of that
channel names the measurement that separates them, in the engineer's terms ("power at
λ 7, pitch 0°, 4 m/s"); each candidate's fingerprint (:attr:`calib.effects.base.Effect.fingerprint`)
says the same in words.

The separation of a probe is

.. math::
    s = |y_a − y_b| \\,/\\, (ρ_c\\, \\max(|\\bar y|, 0.1 \\max_{probes} |\\bar y|))

with ρ_c the channel's relative noise-plus-tolerance (the median σ/|y| of the measured
channel; for a channel not measured, the median over the measured channels) and ȳ the two
predictions' mean: s > 1 means one measurement at that probe, with the campaign's
accuracy, tells the candidates apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.types import OperatingConditions

#: Tip-speed ratios and pitch angles probed, relative to the measured envelope: λ from 0.75 λ_min
#: (at least 1.5) to 1.25 λ_max; pitch 2 deg below to 4 deg above the measured; each at the
#: rotor-speed limits and the measured median, where the wind speed stays in its limits
#: (:func:`probe_limits`).
PROBE_TSR_POINTS = 7
PROBE_FLOOR = 0.1


@dataclass(frozen=True)
class Probe:
    """Where two candidates' predictions differ most (one measurement that separates them)."""

    channel: str
    tip_speed_ratio: float
    pitch: float                 # [deg]
    wind_speed: float            # [m/s]
    values: tuple                # (candidate a, candidate b) [channel unit]
    separation: float            # |y_a − y_b| against the noise-plus-tolerance [-]
    kind: str                    # "measured point, another channel" / "another operating point"

    def words(self, names: tuple, unit: str = "") -> str:
        a, b = self.values
        rel = 100.0 * (a - b) / max(abs(0.5 * (a + b)), 1e-300)
        u = f" {unit}" if unit and unit != "-" else ""
        return (f"{self.channel} at λ {self.tip_speed_ratio:.3g}, pitch {self.pitch:.3g} deg, {self.wind_speed:.3g} m/s "
                f"({self.kind}): {names[0]} {a:.4g}{u}, {names[1]} {b:.4g}{u} ({rel:+.2g} %, {self.separation:.2g}× "
                f"the noise and model-form tolerance)")


def probe_limits(conditions: OperatingConditions, schedule=None) -> tuple[tuple, tuple, str]:
    """The rotor-speed and wind-speed ranges a probe must stay in, and where they come from.

    With the rotor's steady schedule (:class:`calib.rotor.geometry.OperatingSchedule`): its
    rotor-speed limits and its cut-in to cut-out wind speeds. Without one (a wind-tunnel model, an
    FMU): the rotor speeds the campaign ran at, and half the lowest to 1.5 times the highest
    measured wind speed.

    Returns
    -------
    rpm : (float, float)
        [rpm].
    wind : (float, float)
        [m/s].
    words : str
        The limits and their source, for the separation's text.
    """
    rpm, v = conditions.rotor_speed, conditions.wind_speed
    if schedule is not None:
        lo, hi = float(schedule.min_rotor_speed), float(schedule.max_rotor_speed)
        wind = (float(schedule.cut_in), float(schedule.cut_out))
        return (lo, hi), wind, (f"within the rotor's schedule: rotor speed {lo:.3g}–{hi:.3g} rpm, wind speed "
                                f"{wind[0]:.3g}–{wind[1]:.3g} m/s")
    lo, hi = float(rpm.min()), float(rpm.max())
    wind = (0.5 * float(v.min()), 1.5 * float(v.max()))
    speeds = f"{lo:.3g} rpm" if np.isclose(lo, hi) else f"{lo:.3g}–{hi:.3g} rpm"
    return (lo, hi), wind, (f"within the campaign's rotor speeds ({speeds}; no schedule of the rotor's limits) and "
                            f"wind speeds {wind[0]:.3g}–{wind[1]:.3g} m/s")


def probe_conditions(conditions: OperatingConditions, radius: float, schedule=None) -> OperatingConditions:
    """Operating points around and beyond the measured envelope (see :data:`PROBE_TSR_POINTS`),
    inside the operating limits of :func:`probe_limits`.

    Parameters
    ----------
    conditions : OperatingConditions
        The measured points.
    radius : float
        Rotor radius [m].
    schedule : OperatingSchedule, optional
        The rotor's steady schedule (its rotor-speed and wind-speed limits).

    Returns
    -------
    OperatingConditions
        λ × pitch × rotor speed (the limits and the measured median), each at the wind speed
        V = Ω R / λ, those with V inside the limits (air density and yaw: the measured medians).
    """
    (rpm_lo, rpm_hi), (v_lo, v_hi), _ = probe_limits(conditions, schedule)
    lam = conditions.tip_speed_ratio(radius)
    pitch = conditions.pitch
    lams = np.linspace(max(1.5, 0.75 * lam.min()), 1.25 * lam.max(), PROBE_TSR_POINTS)
    pitches = np.unique(np.round([pitch.min() - 2.0, np.median(pitch), pitch.max() + 4.0], 6))
    rpms = np.unique(np.round([rpm_lo, float(np.clip(np.median(conditions.rotor_speed), rpm_lo, rpm_hi)), rpm_hi], 6))
    L, P, W = (a.ravel() for a in np.meshgrid(lams, pitches, rpms, indexing="ij"))
    V = W * np.pi / 30.0 * radius / L
    keep = (V >= v_lo) & (V <= v_hi)
    return OperatingConditions(V[keep], W[keep], P[keep], float(np.median(conditions.air_density)),
                               float(np.median(conditions.yaw)))


def separating_probes(values_a: np.ndarray, values_b: np.ndarray, conditions: OperatingConditions,
                      channels: list, measured_channels: list, relative_noise: dict, n_measured: int,
                      radius: float) -> list[Probe]:
    """The probe of largest separation for each kind: measured points with a channel not
    measured, and other operating points (measured channels or not).

    Parameters
    ----------
    values_a, values_b : ndarray, shape (n_probes, n_channels)
        The two fitted candidates' predictions [channel units].
    conditions : OperatingConditions
        The probes: the first ``n_measured`` are the measured points.
    channels : list of str
        The predicted channels.
    measured_channels : list of str
    relative_noise : dict
        Measured channel -> relative noise-plus-tolerance [-].
    n_measured : int
    radius : float
        [m]

    Returns
    -------
    list of Probe
        Best first; empty when nothing could be compared.
    """
    rho_default = float(np.median(list(relative_noise.values()))) if relative_noise else 0.01
    lam = conditions.tip_speed_ratio(radius)
    best: dict[str, Probe] = {}
    for j, c in enumerate(channels):
        a, b = values_a[:, j], values_b[:, j]
        mean = np.abs(0.5 * (a + b))
        ok = np.isfinite(a) & np.isfinite(b)
        if not ok.any():
            continue
        floor = PROBE_FLOOR * float(np.max(mean[ok]))
        if not floor > 0:
            continue
        s = np.where(ok, np.abs(a - b) / (relative_noise.get(c, rho_default) * np.maximum(mean, floor)), -1.0)
        is_measured_point = np.arange(len(s)) < n_measured
        for kind, mask in (("measured point, another channel", is_measured_point & (c not in measured_channels)),
                           ("another operating point", ~is_measured_point)):
            if not mask.any():
                continue
            k = int(np.flatnonzero(mask)[np.argmax(s[mask])])
            if s[k] < 0:
                continue
            probe = Probe(c, float(lam[k]), float(conditions.pitch[k]), float(conditions.wind_speed[k]),
                          (float(a[k]), float(b[k])), float(s[k]), kind)
            if kind not in best or probe.separation > best[kind].separation:
                best[kind] = probe
    return sorted(best.values(), key=lambda p: -p.separation)


def envelope_words(conditions: OperatingConditions, radius: float) -> str:
    """The measured envelope in words ("λ 3-11, pitch -1-8 deg, 4.5-17 m/s")."""
    lam = conditions.tip_speed_ratio(radius)

    def span(x, fmt=".3g"):
        lo, hi = float(np.min(x)), float(np.max(x))
        return f"{lo:{fmt}}" if np.isclose(lo, hi) else f"{lo:{fmt}} to {hi:{fmt}}"

    return f"λ {span(lam)}, pitch {span(conditions.pitch)} deg, {span(conditions.wind_speed)} m/s"
