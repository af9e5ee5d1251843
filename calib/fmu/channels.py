"""Channels of an FMU model: channel names -> mapped signals, run outcomes -> channel values.

A channel is the steady window mean of a mapped output (``power`` [W], ``thrust`` [N] ...) or of
a spanwise station (``fn@<r/R>`` [N/m]), or an azimuth harmonic of either: amplitude
``<output>_1p``, ``_2p``, ``_3p`` (unit of the output) and phase ``<output>_1p_phase`` ... [deg].
:func:`channel_specs` resolves channel names against a :class:`~calib.fmu.mapping.Mapping`
(:func:`signal_of` per base name) and :func:`offered_channels` lists them; :func:`channel_values` reads the channels from the
:class:`~calib.fmu.plan.RunOutcome` of runs, and :func:`evaluation_of` makes the
:class:`~calib.types.Evaluation` of a call from its results. Nothing here runs the FMU.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from calib.errors import InputError
from calib.fmu import plan as fp
from calib.fmu.mapping import Mapping
from calib.types import Channel, Evaluation, OperatingConditions, Status

#: azimuth-harmonic channel suffixes -> harmonic order
HARMONIC_SUFFIXES = {f"_{n}p": n for n in fp.HARMONIC_ORDERS}
#: mapped outputs that are not channels
NOT_CHANNELS = ("azimuth", "aero_failures")


def signal_of(m: Mapping, base: str, spanwise_eta: Callable) -> tuple:
    """(signal key, unit) of a base output name ((None, None) when the mapping offers none)."""
    if base in m.outputs and base not in NOT_CHANNELS:
        return ("out", base), m.outputs[base].channel_unit
    if base.startswith("fn@") and "normal_force" in m.spanwise:
        eta = spanwise_eta("normal_force")
        if eta is not None:
            labels = [f"{e:.2f}" for e in eta]
            label = base[3:]
            try:
                label = f"{float(label):.2f}"
            except ValueError:
                pass
            if label in labels:
                return ("span", "normal_force", labels.index(label)), "N/m"
    return None, None


def channel_specs(m: Mapping, channels, spanwise_eta: Callable, available: Callable, fmu_name: str) -> list:
    """Per channel: (name, signal key, kind "mean" / "amplitude" / "phase", harmonic order, unit).

    ``spanwise_eta(name)``: the r/R of a spanwise output's stations (None when unknown);
    ``available()``: the channel names offered, for the error.
    """
    if channels is None:
        channels = [c for c in ("power", "thrust") if c in m.outputs] or \
                   [c for c in m.outputs if c not in NOT_CHANNELS][:1]
    if isinstance(channels, str):
        channels = [channels]
    if not channels:
        raise InputError("at least one channel is needed", "FmuModel", field="channels")
    specs = []
    for name in channels:
        base, kind, order = name, "mean", 0
        if name.endswith("_phase"):
            stem = name[: -len("_phase")]
            for suf, n in HARMONIC_SUFFIXES.items():
                if stem.endswith(suf):
                    base, kind, order = stem[: -len(suf)], "phase", n
        else:
            for suf, n in HARMONIC_SUFFIXES.items():
                if name.endswith(suf) and name[: -len(suf)]:
                    cand = name[: -len(suf)]
                    if signal_of(m, cand, spanwise_eta)[0] is not None:
                        base, kind, order = cand, "amplitude", n
        key, unit = signal_of(m, base, spanwise_eta)
        if key is None:
            raise InputError(f"channel {name!r} is not provided by {fmu_name} through "
                             f"{Path(m.source).name}; available: {', '.join(available())}",
                             m.source, field="outputs")
        specs.append((name, key, kind, order, "deg" if kind == "phase" else unit))
    return specs


def offered_channels(m: Mapping, spanwise_eta: Callable) -> list[str]:
    """Channel names a mapping offers: its outputs, ``fn@<r/R>`` per station (when the stations and the
    rotor radius are known), and the harmonics as patterns (``<output>_1p``, ``<output>_1p_phase`` ...).

    ``spanwise_eta(name)``: the r/R of a spanwise output's stations (None when unknown).
    """
    base = [n for n in m.outputs if n not in NOT_CHANNELS]
    if "normal_force" in m.spanwise and m.rotor_radius is not None:
        eta = spanwise_eta("normal_force")
        if eta is not None:
            base += [f"fn@{e:.2f}" for e in eta]
    return base + [f"<output>{s}" for s in HARMONIC_SUFFIXES] + [f"<output>{s}_phase" for s in HARMONIC_SUFFIXES]


def channel_values(outcomes: list, specs: list, keys_for_values: dict) -> np.ndarray:
    """Channel values of run outcomes.

    Parameters
    ----------
    outcomes : list of RunOutcome
        One run per row (``mean`` and complex ``harmonics`` of every signal of the plan).
    specs : list of tuple
        The channels (:func:`channel_specs`).
    keys_for_values : dict
        Signal key -> its index in the plan's signals (:func:`calib.fmu.signals.make_plan`).

    Returns
    -------
    ndarray, shape (n_runs, n_channels)
        Means and harmonic amplitudes [unit of the channel], phases [deg].
    """
    mean = np.array([o.mean for o in outcomes])
    harm = np.array([o.harmonics for o in outcomes])
    out = np.empty((len(outcomes), len(specs)))
    for c, (_, key, kind, order, _) in enumerate(specs):
        i = keys_for_values[key]
        if kind == "mean":
            out[:, c] = mean[:, i]
        elif kind == "amplitude":
            out[:, c] = np.abs(harm[:, i, order - 1])
        else:
            out[:, c] = np.degrees(np.angle(harm[:, i, order - 1]))
    return out


def evaluation_of(results: list, conditions: OperatingConditions, specs: list, keys_for_values: dict,
                  channels: tuple[Channel, ...], alpha_eta) -> Evaluation:
    """The :class:`~calib.types.Evaluation` of a call: the channels of its base runs, a status per point.

    Parameters
    ----------
    results : list of PointResult
        One per operating point (its ``base`` run, ``perturbations``, ``restarts``).
    conditions : OperatingConditions
        The operating points.
    specs : list of tuple
        The channels (:func:`channel_specs`).
    keys_for_values : dict
        Signal key -> its index in the plan's signals (:func:`calib.fmu.signals.make_plan`).
    channels : tuple of Channel
        The channels' names and units.
    alpha_eta : ndarray or None
        r/R [-] of the stations whose angles of attack the extras carry (the correction field's), or None.

    Returns
    -------
    Evaluation
        Values NaN where the status is not converged; a point at rotor speed 0 is ``INVALID_INPUT``
        when a channel is an azimuth harmonic. Extras: ``restarts`` (worker restarts), ``wall_time``
        [s] (all runs of the point), and with ``alpha_eta`` and angles of attack read ``alpha_deg``
        (n_points, n_stations) [deg] and ``eta`` [-].
    """
    outcomes = [r.base for r in results]
    values = channel_values(outcomes, specs, keys_for_values)
    status = np.array([o.status for o in outcomes], int)
    messages = [o.message for o in outcomes]
    needs_harmonics = any(kind != "mean" for _, _, kind, _, _ in specs)
    if needs_harmonics:
        for k in np.flatnonzero((conditions.rotor_speed <= 0) & (status == Status.CONVERGED)):
            status[k] = Status.INVALID_INPUT
            messages[k] = "azimuth harmonics need a turning rotor (rotor speed 0)"
    values[status != Status.CONVERGED] = np.nan
    return Evaluation(values, status, tuple(messages), channels, _extras(outcomes, results, keys_for_values, alpha_eta))


def _extras(outcomes: list, results: list, keys_for_values: dict, alpha_eta) -> dict:
    """Worker restarts, wall times and (with ``alpha_eta``) the angles of attack at the stations."""
    extras = {"restarts": np.array([r.restarts for r in results], int),
              "wall_time": np.array([sum(o.wall for o in [r.base, *[x for x in r.perturbations if x]] if o)
                                     for r in results])}
    if alpha_eta is not None:
        keys = sorted((k for k in keys_for_values if k[0] == "span" and k[1] == "angle_of_attack"), key=lambda k: k[2])
        idx = [keys_for_values[k] for k in keys]
        if idx:
            alpha = np.array([o.mean[idx] for o in outcomes])
            extras["alpha_deg"], extras["eta"] = alpha, alpha_eta
    return extras
