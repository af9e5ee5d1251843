"""Finite differences (central or forward) of an FMU model's steady channels with respect to its parameters.

:func:`perturbed_vectors` gives the parameter vectors of the perturbed runs (steps
``relative_step`` × each parameter's ``scale``, one-sided inside a bound) and
:func:`sensitivities` the Jacobian from those runs, point by point: a point whose perturbed run
failed gets that run's status, phases are differenced on the circle. How the runs are simulated
(cold or warm-started from the settled base state) is :class:`calib.fmu.model.FmuModel`'s affair.

Jacobians are central differences with steps ``relative_step`` ×
each parameter's ``scale`` (one-sided inside a bound), or forward differences against the point's
base run (``differences = "forward"`` in ``[jacobian]``: one run per parameter instead of two, an
O(h) error instead of O(h²); for an FMU whose second-order term is far below the noise). With ``warm_start`` (``[jacobian]`` of the mapping,
or ``jacobian={"warm_start": True}``) the base run of each point saves its settled state and
every perturbed run restores it, sets the perturbed parameters and settles only
``perturbation_settle_revolutions`` before averaging ``perturbation_average_revolutions``
(docs/theory.md, FMUs). That is exact when a parameter step acts at once (quasi-steady physics) and
wrong by the lag where the FMU filters it (dynamic inflow): the bundled mappings keep it off
and say why. A point's runs are one executor task, so the state never leaves its worker
except serialized, to resume after a fault. FMI directional derivatives are not used: co-simulation FMUs give them for
inputs and states at one instant, not for the steady window averages with respect to
parameters; whether the FMU offers them is reported by :attr:`calib.fmu.model.FmuModel.jacobian_method`
(the bundled FMUs and PythonFMU's do not).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from calib.fmu.channels import channel_values
from calib.types import Evaluation, Parameter, Status


def perturbed_vectors(p: np.ndarray, parameters: Sequence[Parameter], relative_step: float,
                      differences: str = "central") -> tuple[list[np.ndarray], np.ndarray]:
    """Parameter vectors of the perturbed runs and the steps between them.

    Parameters
    ----------
    p : ndarray, shape (n_params,)
        The base point [package units].
    parameters : sequence of Parameter
        Bounds and scales of the parameters [package units].
    relative_step : float
        Step as a fraction of each parameter's ``scale`` [-].
    differences : {"central", "forward"}
        Central: two runs per parameter; forward: one (up, or down where up leaves the bounds).

    Returns
    -------
    vectors : list of ndarray
        Central: 2 n_params vectors, ``p`` with parameter j moved up, then down (inside its bounds),
        for j = 0, 1, ...; forward: n_params vectors, parameter j moved by ±h [package units].
    steps : ndarray, shape (n_params,)
        Central: up minus down value of each parameter; forward: perturbed minus base value
        [package units].
    """
    lower = np.array([q.lower for q in parameters])
    upper = np.array([q.upper for q in parameters])
    h = relative_step * np.array([q.scale for q in parameters])
    plus, minus = np.minimum(p + h, upper), np.maximum(p - h, lower)
    vectors = []
    if differences == "forward":
        moved = np.where(p + h <= upper, p + h, np.maximum(p - h, lower))
        for j in range(p.size):
            q = p.copy()
            q[j] = moved[j]
            vectors.append(q)
        return vectors, moved - p
    for j in range(p.size):
        for x in (plus[j], minus[j]):
            q = p.copy()
            q[j] = x
            vectors.append(q)
    return vectors, plus - minus


def failed_perturbation(runs: list, names: Sequence[str], per_parameter: int = 2) -> tuple[int, str] | None:
    """Status and message of the first failed perturbed run of a point (None when all are ok).

    Parameters
    ----------
    runs : list of RunOutcome or None
        The perturbed runs in the order of :func:`perturbed_vectors` (None: never run).
    names : sequence of str
        Parameter names, for the message.
    """
    bad = [j for j, o in enumerate(runs) if o is None or not o.ok]
    if not bad:
        return None
    j = bad[0]
    o = runs[j]
    status = o.status if o is not None else Status.SIMULATION_FAILED
    sign = "" if per_parameter == 1 else "+" if j % 2 == 0 else "-"
    return status, (f"perturbed run ({sign}{names[j // per_parameter]}) failed: "
                    f"{o.message if o is not None else 'not run'}")


def central_differences(y: np.ndarray, steps: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Sensitivities of one point from its perturbed channel values.

    Parameters
    ----------
    y : ndarray, shape (2 n_params, n_channels)
        Channel values of the perturbed runs (up, down per parameter) [unit of the channel].
    steps : ndarray, shape (n_params,)
        Up minus down value of each parameter [package units].
    phase : ndarray of bool, shape (n_channels,)
        Phase channels [deg], whose differences are wrapped into [-180, 180).

    Returns
    -------
    ndarray, shape (n_channels, n_params)
        ``d y[c] / d p[j]`` [unit of the channel / unit of the parameter].
    """
    d = y[0::2] - y[1::2]
    d[:, phase] = (d[:, phase] + 180.0) % 360.0 - 180.0
    return (d / steps[:, None]).T


def forward_differences(y: np.ndarray, y0: np.ndarray, steps: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """Sensitivities of one point from one perturbed run per parameter and its base run.

    ``y`` (n_params, n_channels): perturbed channel values; ``y0`` (n_channels,): the base run's;
    ``steps`` (n_params,): perturbed minus base parameter value; phases wrapped as in
    :func:`central_differences`. Returns ``d y[c] / d p[j]``, shape (n_channels, n_params).
    """
    d = y - y0[None, :]
    d[:, phase] = (d[:, phase] + 180.0) % 360.0 - 180.0
    return (d / steps[:, None]).T


def sensitivities(results: list, ev: Evaluation, steps: np.ndarray, specs: list, keys_for_values: dict,
                  names: Sequence[str], differences: str = "central") -> tuple[Evaluation, np.ndarray]:
    """Central-difference sensitivities ``G[k, c, j] = d y[k, c] / d p[j]`` from the runs of each point.

    Parameters
    ----------
    results : list of PointResult
        One per operating point, with its perturbed runs.
    ev : Evaluation
        The base runs' evaluation.
    steps : ndarray, shape (n_params,)
        Up minus down value of each parameter (:func:`perturbed_vectors`) [package units].
    specs : list of tuple
        The channels (:func:`calib.fmu.channels.channel_specs`).
    keys_for_values : dict
        Signal key -> its index in the plan's signals.
    names : sequence of str
        Parameter names, for messages.

    Returns
    -------
    evaluation : Evaluation
        ``ev``, where a point whose perturbed run failed gets that run's status and message
        (and NaN values): its sensitivities are unknown.
    G : ndarray, shape (n_points, n_channels, n_params)
        NaN on failed points.
    """
    G = np.full((len(results), len(ev.channels), steps.size), np.nan)
    status, messages = ev.status.copy(), list(ev.messages)
    phase = np.array([kind == "phase" for _, _, kind, _, _ in specs])
    for k, r in enumerate(results):
        if status[k] != Status.CONVERGED:
            continue
        failure = failed_perturbation(r.perturbations, names, 1 if differences == "forward" else 2)
        if failure is not None:
            status[k], messages[k] = failure
            continue
        y = channel_values(r.perturbations, specs, keys_for_values)
        G[k] = (forward_differences(y, channel_values([r.base], specs, keys_for_values)[0], steps, phase)
                if differences == "forward" else central_differences(y, steps, phase))
    values = ev.values.copy()
    values[status != Status.CONVERGED] = np.nan
    return Evaluation(values, status, tuple(messages), ev.channels, ev.extras), G


def method_words(differences: str, relative_step: float, warm: bool, offers_directional_derivatives: bool) -> str:
    """How an FMU model differentiates, and why (:attr:`calib.fmu.model.FmuModel.jacobian_method`)."""
    dd = ("the FMU offers directional derivatives, but of instantaneous outputs with respect to inputs and "
          "states, not of steady window averages with respect to parameters: not used"
          if offers_directional_derivatives else "the FMU offers no directional derivatives")
    how = "warm-started from the settled base state" if warm else "each perturbed run settled from scratch"
    return f"{differences} differences, steps {relative_step:g} x parameter scale, {how}; {dd}"
