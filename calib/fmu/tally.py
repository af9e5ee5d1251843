"""What an FMU model's simulations cost: counts, model time, busy worker time, wall time.

:class:`SimulationTally` lives with the model (:class:`calib.fmu.model.FmuModel`), where the
executor is called: each call adds the runs its points made (base and perturbed runs, as the
workers report them in :class:`~calib.fmu.plan.PointResult`), the model time they simulated,
the time the workers were busy with them and the wall time of the call. Parallel efficiency is
busy worker time / (wall time x workers): 1 when every worker simulated all the time, less when
workers waited (a serial tail at the end of a call, start-up, the planner's own work between
calls is not counted: it is outside the calls).
"""

from __future__ import annotations

import time
from dataclasses import dataclass


@dataclass
class SimulationTally:
    """Counts of the simulations run through one model (all its ``evaluate`` and ``jacobian`` calls).

    Attributes
    ----------
    calls : int
        Executor calls (one per model call that simulated anything).
    tasks : int
        Operating points sent to the executor (one task each).
    simulations : int
        Runs made (base and perturbed runs; quarantined points are not simulated).
    reused : int
        Base runs not simulated again: their outcome was known (:mod:`calib.fmu.base_runs`).
    reused_perturbed : int
        Perturbed runs not simulated again (cold runs at the same point and parameter values known).
    simulated_s : float
        Model time simulated, settling included [s].
    busy_s : float
        Wall time the workers spent on the tasks (instance creation included) [s].
    wall_s : float
        Wall time of the executor calls [s].
    workers : int
        Workers of the executor (the largest seen).
    """

    calls: int = 0
    tasks: int = 0
    simulations: int = 0
    reused: int = 0
    reused_perturbed: int = 0
    simulated_s: float = 0.0
    busy_s: float = 0.0
    wall_s: float = 0.0
    workers: int = 1

    def timed_map(self, executor, fn, jobs: list, progress=None) -> list:
        """``executor.map(fn, jobs, progress)``, timed and recorded (nothing for no jobs)."""
        if not jobs:
            return []
        t0 = time.perf_counter()
        done = executor.map(fn, jobs, progress)
        self.record(done, time.perf_counter() - t0, getattr(executor, "workers", 1))
        return done

    def record(self, results, wall: float, workers: int) -> None:
        """Add one executor call: its :class:`~calib.fmu.plan.PointResult` list, its wall time [s] and the
        executor's worker count (added to this process's :func:`process_totals` too)."""
        if self is not _TOTALS:
            _TOTALS.record(results, wall, workers)
        self.calls += 1
        self.tasks += len(results)
        self.wall_s += float(wall)
        self.workers = max(self.workers, int(workers or 1))
        for r in results:
            runs = r.outcomes()
            self.simulations += sum(1 for o in runs if o.fault != "quarantined" and not o.reused)
            self.simulated_s += sum(o.simulated for o in runs)
            self.busy_s += r.busy

    def add_reused(self, base: int, perturbed: int) -> None:
        """Count runs not simulated again (known outcomes, :mod:`calib.fmu.base_runs`), here and in
        :func:`process_totals`."""
        for t in ((self, _TOTALS) if self is not _TOTALS else (self,)):
            t.reused += int(base)
            t.reused_perturbed += int(perturbed)

    @property
    def efficiency(self) -> float | None:
        """Busy worker time / (wall time x workers) [-]; None before any call."""
        return self.busy_s / (self.wall_s * self.workers) if self.wall_s > 0 else None

    def summary(self) -> dict:
        """Plain (JSON-able) dict: the attributes and ``parallel_efficiency``."""
        return {"calls": self.calls, "tasks": self.tasks, "simulations": self.simulations,
                "reused_base_runs": self.reused, "reused_perturbed_runs": self.reused_perturbed,
                "simulated_s": self.simulated_s, "busy_worker_s": self.busy_s, "wall_s": self.wall_s,
                "workers": self.workers, "parallel_efficiency": self.efficiency}


_TOTALS = SimulationTally()


def process_totals(reset: bool = False) -> dict:
    """What every FMU model of this process simulated so far (all their executor calls), as
    :meth:`SimulationTally.summary`; with ``reset`` start
    again from zero. For a benchmark that runs models it does not hold (e.g. a diagnosis)."""
    out = _TOTALS.summary()
    if reset:
        _TOTALS.__init__()
    return out


def tally_sentence(summary: dict) -> str:
    """One line of :meth:`SimulationTally.summary` for the report and the console."""
    eff = summary["parallel_efficiency"]
    reused = summary.get("reused_base_runs", 0)
    perturbed = summary.get("reused_perturbed_runs", 0)
    return (f"{summary['simulations']} simulations ({summary['tasks']} points in {summary['calls']} calls"
            + (f", {reused} base runs reused" if reused else "")
            + (f", {perturbed} perturbed runs reused" if perturbed else "") + "), "
            f"{summary['simulated_s']:.4g} s simulated, {summary['busy_worker_s']:.3g} s busy on "
            f"{summary['workers']} worker(s) in {summary['wall_s']:.3g} s wall: parallel efficiency "
            + ("n/a" if eff is None else f"{eff:.2f}"))
