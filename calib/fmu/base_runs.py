"""Settled base runs kept for reuse: an FMU point simulated once at a parameter vector is not simulated again.

A cold base run (reset, parameters and inputs set, settled, averaged) is deterministic: the same plan
(FMU content hash, settings, switches, signals, window: :attr:`~calib.fmu.plan.SimulationPlan.key`), the
same inputs and parameter values give the same outcome bit for bit, whatever the executor or worker.
So the planner keeps the outcomes of such runs (a :class:`BaseRunCache`: one per model by default, or
one shared by the models of a run, :func:`shared_by`) and a later call at the same point and parameters
reuses them: the unit check's evaluation at the nominal parameters serves the calibration's first
evaluation; a Gauss-Newton step evaluated at a trial vector serves the base runs of the Jacobian taken
there when it is accepted. A reused outcome is marked ``reused`` (not counted as a simulation, nor as a
healthy wall time).
"""

from __future__ import annotations

import weakref
from collections import OrderedDict
from dataclasses import replace

from calib.fmu.plan import PointResult, PointTask, RunOutcome

#: Outcomes kept (the oldest dropped first): a few hundred model calls of a few dozen points
MAX_KEPT = 20_000


class BaseRunCache:
    """Outcomes of cold base runs by (plan key, inputs, parameter values, rotor speed); bounded, oldest out."""

    def __init__(self, max_kept: int = MAX_KEPT):
        self.max_kept = int(max_kept)
        self._runs: OrderedDict = OrderedDict()
        self.hits = 0

    @staticmethod
    def _key(plan_key: str, task: PointTask) -> tuple:
        return (plan_key, task.inputs, task.base, float(task.rotor_speed))

    def get(self, plan_key: str, task: PointTask) -> RunOutcome | None:
        """A copy of the kept outcome of ``task``'s base run, marked reused (None: not kept, or the task
        starts from a saved state)."""
        if task.start_state is not None or task.base_state is not None:
            return None
        o = self._runs.get(self._key(plan_key, task))
        if o is None:
            return None
        self.hits += 1
        return replace(o, reused=True, wall=0.0, instantiation=0.0, simulated=0.0)

    def put(self, plan_key: str, task: PointTask, outcome: RunOutcome | None) -> None:
        """Keep a base run simulated from scratch that met no fault (its status came from its outputs)."""
        if outcome is None or outcome.fault or outcome.reused or task.start_state is not None:
            return
        key = self._key(plan_key, task)
        self._runs[key] = outcome
        self._runs.move_to_end(key)
        while len(self._runs) > self.max_kept:
            self._runs.popitem(last=False)

    def split(self, plan_key: str, tasks: list, run: list, results: list, reused: int,
              cold: bool) -> tuple[list, int]:
        """The indices of ``run`` still to send to the executor, and ``reused`` plus the base runs reused here.

        A point of ``tasks`` whose base run is kept is not simulated again: an evaluation's result is
        filled into ``results`` here; a Jacobian's task (replaced in ``tasks``) takes the known outcome
        along when its perturbed runs start ``cold`` anyway (warm start off or no FMU state), so that its
        result is the same bit for bit.
        """
        send = []
        for k in run:
            t = tasks[k]
            known = self.get(plan_key, t) if (cold or not t.perturbations) and not t.keep_state else None
            if known is None:
                send.append(k)
                continue
            reused += 1
            if t.perturbations:
                tasks[k] = replace(t, known_base=known, warm=False)
                send.append(k)
            else:
                results[k] = PointResult(t.index, known, [])
        return send, reused

    def clear(self) -> None:
        self._runs.clear()


_SHARED: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def shared_by(executor) -> BaseRunCache:
    """The cache shared by the models that run on ``executor`` (the models of one workflow run share it;
    it goes with the executor)."""
    cache = _SHARED.get(executor)
    if cache is None:
        cache = _SHARED[executor] = BaseRunCache()
    return cache
