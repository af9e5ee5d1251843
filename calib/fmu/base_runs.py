"""Settled base runs kept for reuse: an FMU point simulated once at a parameter vector is not simulated again.

A cold base run (reset, parameters and inputs set, settled, averaged) is deterministic: the same plan
(FMU content hash, settings, switches, signals, window: :attr:`~calib.fmu.plan.SimulationPlan.key`), the
same inputs and parameter values give the same outcome bit for bit, whatever the executor or worker.
The same holds for a cold perturbed run (a cold run at the perturbed values).
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
    """Outcomes of cold runs by (plan key, inputs, parameter values, rotor speed); bounded, oldest out.

    A cold perturbed run of a Jacobian (warm start off, or an FMU without state) is a cold run at the
    perturbed parameter values: it is kept and reused like a base run, so a Jacobian taken again at the
    same point and parameters (by another model of the same plan, e.g. a diagnosis candidate, or after the
    fit) simulates nothing, and a base run serves a perturbed run at the same values. ``canon`` (a model's
    :meth:`calib.fmu.binding.ParameterBinding.canonical`) makes the parameter values a key that does not
    depend on which parameters the model calibrates (the values off the FMU's start values).
    """

    def __init__(self, max_kept: int = MAX_KEPT):
        self.max_kept = int(max_kept)
        self._runs: OrderedDict = OrderedDict()
        self.hits = 0

    @staticmethod
    def _key(plan_key: str, task: PointTask, parameters=None, canon=None) -> tuple:
        values = task.base if parameters is None else parameters
        return (plan_key, task.inputs, values if canon is None else canon(values), float(task.rotor_speed))

    def get(self, plan_key: str, task: PointTask, parameters=None, canon=None) -> RunOutcome | None:
        """A copy of the kept outcome of ``task``'s base run (or of a cold run of that point at ``parameters``),
        marked reused (None: not kept, or the task starts from a saved state)."""
        if task.start_state is not None or task.base_state is not None:
            return None
        o = self._runs.get(self._key(plan_key, task, parameters, canon))
        if o is None:
            return None
        self.hits += 1
        return replace(o, reused=True, wall=0.0, instantiation=0.0, simulated=0.0)

    def put(self, plan_key: str, task: PointTask, outcome: RunOutcome | None, parameters=None, canon=None) -> None:
        """Keep a run simulated from scratch (the base run, or a cold run at ``parameters``) that met no fault
        (its status came from its outputs)."""
        if outcome is None or outcome.fault or outcome.reused or task.start_state is not None:
            return
        key = self._key(plan_key, task, parameters, canon)
        self._runs[key] = outcome
        self._runs.move_to_end(key)
        while len(self._runs) > self.max_kept:
            self._runs.popitem(last=False)

    def put_result(self, plan_key: str, task: PointTask, result: PointResult, cold: bool, canon=None) -> None:
        """Keep the runs of ``result`` (the base run; the perturbed runs too when they ran ``cold``)."""
        self.put(plan_key, task, result.base, canon=canon)
        if cold and task.base_state is None:
            for values, o in zip(task.perturbations, result.perturbations):
                self.put(plan_key, task, o, values, canon)

    def split(self, plan_key: str, tasks: list, run: list, results: list, cold: bool,
              canon=None) -> tuple[list, int, int]:
        """The indices of ``run`` still to send to the executor, and the base and perturbed runs reused here.

        A point of ``tasks`` whose base run is kept is not simulated again: an evaluation's result is
        filled into ``results`` here; a Jacobian's task (replaced in ``tasks``) takes the known outcomes
        along when its perturbed runs start ``cold`` anyway (warm start off or no FMU state), so that its
        result is the same bit for bit; a Jacobian point whose runs are all known is filled in here too.
        """
        send, n_base, n_runs = [], 0, 0
        for k in run:
            t = tasks[k]
            if t.keep_state or not (cold or not t.perturbations):
                send.append(k)
                continue
            known = self.get(plan_key, t, canon=canon)
            runs = tuple(self.get(plan_key, t, q, canon) for q in t.perturbations) if cold and t.perturbations else ()
            n_known = sum(o is not None for o in runs)
            if known is None and not n_known:
                send.append(k)
                continue
            n_base += known is not None
            n_runs += n_known
            if not t.perturbations:
                results[k] = PointResult(t.index, known, [])
            elif known is not None and (n_known == len(runs) or not known.ok):
                results[k] = PointResult(t.index, known, list(runs) if known.ok else [None] * len(runs))
            else:
                tasks[k] = replace(t, known_base=known, known_runs=runs if n_known else None,
                                   warm=False if known is not None else t.warm)
                send.append(k)
        return send, n_base, n_runs

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
