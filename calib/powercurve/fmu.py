"""An FMU result's power curve: :class:`FmuPowerModel`, the FMU behind the ``solve`` the schedules call.

The schedules (:mod:`calib.powercurve.schedule`) call ``solve(p, conditions)`` and read power,
thrust, C_P, C_T and a status per point. An FMU (:class:`calib.fmu.model.FmuModel`) has no such
solve: its ``evaluate`` runs one simulation per point on the model's executor (serial, process pool
or Dask, as the workflow set it) and returns the mapped channels. :class:`FmuPowerModel` turns that
into the solve's answer; the posterior draws then run one ``evaluate`` per draw, every bin of a draw
on the executor at once, and the report states the simulations made
(:meth:`calib.fmu.model.FmuModel.simulation_summary`). Only the fixed-speed and table schedules apply
(the variable-speed schedule re-finds the optimal λ and pitches to rated through many solves: not
offered for an FMU here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["FmuPowerModel", "is_fmu_model"]


def is_fmu_model(model) -> bool:
    """True for a model with ``evaluate`` but no BEM ``solve`` (an FMU)."""
    return hasattr(model, "evaluate") and not hasattr(model, "solve")


@dataclass(frozen=True)
class _Solved:
    power: np.ndarray
    thrust: np.ndarray
    cp: np.ndarray
    ct: np.ndarray
    status: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        return self.status == 0


@dataclass(frozen=True)
class _Radius:
    rotor_radius: float
    name: str = "FMU rotor"
    schedule: object = None


class _Nominal:
    def __init__(self, parameters):
        self._p = np.array([q.nominal for q in parameters], float)

    def nominal(self) -> np.ndarray:
        return self._p.copy()


class FmuPowerModel:
    """An FMU model with the ``solve`` the power-curve schedules call; everything else passes through.

    Parameters
    ----------
    model : FmuModel
        With a ``power`` channel, or ``torque`` (power = torque × Ω); ``thrust`` when mapped.
    source : str
        Named in errors (the result folder).

    Raises
    ------
    InputError
        Neither a power nor a torque channel.

    Notes
    -----
    C_P and C_T need the rotor radius: NaN where the FMU's mapping gives none.
    """

    def __init__(self, model, source: str = "result"):
        self._model = model
        names = [c.name for c in model.channels]
        if "power" not in names and "torque" not in names:
            raise InputError(f"the FMU model's channels ({', '.join(names)}) have neither power nor torque: no power "
                             "curve", source, field="channels")
        radius = getattr(model, "rotor_radius", None)
        radius = float(radius) if radius is not None and np.isfinite(radius) and radius > 0 else float("nan")
        self._names = names
        self.rotor = _Radius(radius)
        self.chain = _Nominal(model.parameters)
        self.simulations_before = self.simulation_count()

    def __getattr__(self, name):
        return getattr(self._model, name)

    def simulation_count(self) -> int:
        """Simulations this FMU model ran so far."""
        return int(self._model.simulation_summary().get("simulations", 0))

    def solve(self, p, conditions: OperatingConditions) -> _Solved:
        """Power [W], thrust [N], C_P, C_T [-] and status per point, from one ``evaluate`` on the executor."""
        ev = self._model.evaluate(p, conditions)
        n = len(conditions)
        col = lambda c: ev.values[:, self._names.index(c)] if c in self._names else np.full(n, np.nan)  # noqa: E731
        omega = np.asarray(conditions.rotor_speed, float) * np.pi / 30.0
        power = col("power") if "power" in self._names else col("torque") * omega
        thrust = col("thrust")
        v = np.asarray(conditions.wind_speed, float)
        rho = np.broadcast_to(np.asarray(conditions.air_density, float), v.shape)
        area = np.pi * self.rotor.rotor_radius ** 2
        with np.errstate(divide="ignore", invalid="ignore"):
            cp = power / (0.5 * rho * area * v ** 3)
            ct = thrust / (0.5 * rho * area * v ** 2)
        status = np.asarray(ev.status, int).copy()
        return _Solved(power, thrust, cp, ct, status)
