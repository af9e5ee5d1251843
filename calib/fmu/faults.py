"""The planner's record of an FMU's faults: quarantine of points that crash or hang.

:class:`FaultLedger` lives with the model (:class:`calib.fmu.model.FmuModel`), where
tasks are planned, so that what is simulated does not depend on the executor: a point
whose simulation crashed the FMU process, hung or got a fatal status is not simulated again
(retried once at most, when the parameters have moved far), and the healthy runs' wall
times set the adaptive timeout (:func:`calib.fmu.plan.adaptive_timeout`).
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from calib.fmu.plan import (DEFAULT_TIMEOUT, HEALTHY_WALLS_KEPT, QUARANTINE_FAULTS, RETRY_DISTANCE, TIMEOUT_FLOOR,
                                     TIMEOUT_MULTIPLE, PointResult, PointTask, RunOutcome, TimeoutPolicy)
from calib.types import CONDITION_FIELDS, Status

log = logging.getLogger("calib.fmu.worker")


def point_key(task: PointTask) -> tuple:
    """Identity of an operating point: the FMU input values and the rotor speed (hashable).

    Every condition the model takes either is an FMU input or must have its default, so two
    points with the same key are the same operating point, and two different points never
    share a key."""
    return (task.inputs, float(task.rotor_speed))


@dataclass
class QuarantineEntry:
    """A point that crashed the FMU process or hung (see :class:`FaultLedger`)."""

    index: int                 # position of the point in the model call where it failed
    conditions: dict           # operating conditions [package units]
    status: int
    fault: str                 # one of QUARANTINE_FAULTS
    run: str                   # which run of the point failed
    message: str
    p: np.ndarray              # parameters where it (last) failed [package units]
    call: int                  # model call (1, 2, ...) where it (last) failed
    timeout: float | None      # timeout in force then [s]
    faults: int = 1            # simulations of the point that faulted
    skipped: int = 0           # times it was not simulated
    retried: bool = False
    retry_call: int | None = None
    retry_outcome: str | None = None   # "failed again" | "recovered"
    active: bool = True

    def as_dict(self) -> dict:
        d = dict(self.__dict__)
        d["conditions"] = dict(self.conditions)
        d["p"] = [float(x) for x in self.p]
        d["status_name"] = Status(self.status).name
        return d


_FAULT_VERBS = {"crash": "crashed the FMU process", "timeout": "hung", "fatal": "got a fatal status"}
_FAULT_COUNTS = {"crash": "crashes", "timeout": "timeouts", "start-timeout": "start_timeouts", "error": "errors",
                 "fatal": "fatal"}


def _run_name(j: int) -> str:
    return "base run" if j < 0 else f"perturbed run {j + 1}"


class FaultLedger:
    """The faults of one model's simulations, kept where tasks are planned (the process that
    holds the model), so that what is simulated does not depend on the executor.

    Quarantine: a point whose simulation crashed the FMU process, hung, or got a fatal status
    (any of its runs) is not simulated again for the rest of the model's lifetime (or until
    :meth:`clear`): later
    calls return its recorded status, with a message saying it is quarantined and why. It is
    retried once at most, when the parameters are *far* from where it failed: some parameter
    has moved at least ``retry_distance`` (1) of its scales, ``max_j |p_j - p_fail,j| /
    scale_j >= 1`` (the scale is the typical size of a meaningful change; Jacobian steps,
    ``relative_step`` x scale <= 0.5 scale, never qualify). A retry that succeeds releases the
    point; one that fails quarantines it for good. Points are keyed by :func:`point_key`: a
    different operating point is never affected.

    Each of those costs a new worker process or a wait for the timeout (a fatal status
    forbids any further FMI call, so the process is replaced as after a crash). An error
    status (fmi2Error, fmi2Discard: an FMI call failed and the process lives on) does not
    quarantine: it costs one run and a new instance, and it often depends on the parameters
    (a vendor FMU refusing a value out of its range), so the point must come back as soon as
    the parameters do; simulating it again gives the same status at the same parameters, so
    evaluations and Jacobians stay consistent. Such points are listed under ``errors`` in
    :meth:`summary` (with fatal ones, which are also quarantined). An instance not created
    within the start timeout says nothing about the point (inputs are set afterwards): not
    quarantined either.

    Adaptive timeout: :meth:`policy` hands workers the wall times of the healthy base runs
    measured so far (the last :data:`HEALTHY_WALLS_KEPT`); the timeout in force is
    :func:`adaptive_timeout` of them.
    """

    def __init__(self, names, scales, configured: float, start_timeout: float = DEFAULT_TIMEOUT, label: str = "FMU",
                 multiple: float = TIMEOUT_MULTIPLE, floor: float = TIMEOUT_FLOOR,
                 retry_distance: float = RETRY_DISTANCE):
        self.names = tuple(names)
        self.scales = np.asarray(scales, float)
        self.label = label
        self.retry_distance = float(retry_distance)
        self._rule = TimeoutPolicy(float(configured), float(multiple), float(floor), (), float(start_timeout))
        self.clear()
        self.walls: deque = deque(maxlen=HEALTHY_WALLS_KEPT)
        self.n_healthy = 0
        self.changes: list[dict] = []
        self._announced = self._rule.configured

    def clear(self) -> None:
        """Forget quarantined points and errors (a new stage); the timeout statistics stay."""
        self.entries: dict = {}
        self.errors: dict = {}
        self.counts = dict(calls=0, points_simulated=0, points_skipped=0, crashes=0, timeouts=0, start_timeouts=0,
                           errors=0, fatal=0, retries=0)

    # -- timeout ------------------------------------------------------------------
    def policy(self) -> TimeoutPolicy:
        return replace(self._rule, walls=tuple(self.walls))

    @property
    def timeout(self) -> float:
        """The simulation timeout in force [s]."""
        return self.policy().timeout()

    def _note_timeout(self) -> None:
        t = self.timeout
        if abs(t - self._announced) <= 0.2 * self._announced:
            return
        med = float(np.median(self.walls))
        self.changes.append({"call": self.counts["calls"], "timeout_s": t, "median_healthy_s": med,
                             "healthy_runs": self.n_healthy})
        log.info("[calib fmu] %s: simulation timeout now %.3g s (%g x the median %.3g s of %d healthy runs, floor %g s, "
                 "configured %g s)", self.label, t, self._rule.multiple, med, self.n_healthy, self._rule.floor,
                 self._rule.configured)
        self._announced = t

    # -- planning -----------------------------------------------------------------
    def _far(self, p: np.ndarray, q: np.ndarray) -> bool:
        return p.size > 0 and float(np.max(np.abs(p - q) / self.scales)) >= self.retry_distance

    def plan(self, tasks, p, n_signals: int):
        """Which tasks to simulate; returns (indices to run, results with the skipped ones filled)."""
        self.counts["calls"] += 1
        p = np.asarray(p, float)
        run, results = [], [None] * len(tasks)
        for k, task in enumerate(tasks):
            e = self.entries.get(point_key(task))
            if e is None or not e.active:
                run.append(k)
            elif not e.retried and self._far(p, e.p):
                self._retry(e, p)
                run.append(k)
            else:
                e.skipped += 1
                results[k] = self._skipped(e, task, n_signals)
        self.counts["points_simulated"] += len(run)
        self.counts["points_skipped"] += len(tasks) - len(run)
        return run, results

    def _retry(self, e: QuarantineEntry, p: np.ndarray) -> None:
        e.retried, e.retry_call = True, self.counts["calls"]
        self.counts["retries"] += 1
        moved = np.abs(p - e.p) / self.scales
        j = int(np.argmax(moved))
        log.info("%s: retrying the quarantined point %s once (%s moved %.3g scales from where it failed)",
                 self.label, _conditions_text(e.conditions), self.names[j], moved[j])

    def _skipped(self, e: QuarantineEntry, task: PointTask, n_signals: int) -> PointResult:
        verb = _FAULT_VERBS[e.fault]
        retry = ("retried once, failed again" if e.retry_outcome == "failed again" else
                 "failed again after its release" if e.retried else
                 f"one retry when a parameter moves >= {self.retry_distance:g} scale")
        msg = (f"quarantined, not simulated: the {e.run} {verb} at this operating point in model call {e.call} "
               f"({retry}): {e.message}")
        return PointResult(task.index, RunOutcome.failed(n_signals, e.status, msg, fault="quarantined"),
                           [None] * len(task.perturbations))

    # -- recording ----------------------------------------------------------------
    def record(self, tasks, results, ran, p, conditions) -> None:
        """Learn from the results of the simulated tasks (``ran``: their indices)."""
        p = np.asarray(p, float)
        for k in ran:
            self._record_point(k, tasks[k], results[k], p, conditions)
        self._note_timeout()

    def _record_point(self, k: int, task: PointTask, r: PointResult, p, conditions) -> None:
        runs = [r.base, *r.perturbations]
        for o in r.outcomes():
            key = _FAULT_COUNTS.get(o.fault)
            if key:
                self.counts[key] += 1
        if r.base is not None and r.base.ok and task.start_state is None and not r.base.reused:
            self.walls.append(r.base.wall - r.base.instantiation)
            self.n_healthy += 1
        where = {f: float(getattr(conditions, f)[k]) for f in CONDITION_FIELDS}
        hit = next((j for j, o in enumerate(runs) if o is not None and o.fault in QUARANTINE_FAULTS), None)
        e = self.entries.get(point_key(task))
        if hit is not None:
            self._quarantine(k, task, runs[hit], hit - 1, p, where, r.timeout)
        elif e is not None and e.active:
            e.active, e.retry_outcome = False, "recovered"
            log.info("%s: the quarantined point %s simulated again without fault: released", self.label,
                     _conditions_text(e.conditions))
        err = next((j for j, o in enumerate(runs) if o is not None and o.fault in ("error", "fatal")), None)
        if err is not None:
            self._error(task, runs[err], err - 1, where)

    def _quarantine(self, k, task, o: RunOutcome, j: int, p, where: dict, timeout) -> None:
        key = point_key(task)
        e = self.entries.get(key)
        call = self.counts["calls"]
        if e is None:
            e = self.entries[key] = QuarantineEntry(k, where, o.status, o.fault, _run_name(j), o.message, p.copy(),
                                                    call, timeout)
        else:
            e.faults += 1
            e.status, e.fault, e.run, e.message, e.p, e.call, e.timeout = (o.status, o.fault, _run_name(j),
                                                                           o.message, p.copy(), call, timeout)
            e.active = True
            if e.retry_call == call:
                e.retry_outcome = "failed again"
        log.warning("%s: operating point %s quarantined: the %s %s (%s); not simulated again%s", self.label,
                    _conditions_text(where), e.run, _FAULT_VERBS[o.fault],
                    o.message, "" if e.retried else f" unless a parameter moves >= {self.retry_distance:g} scale")

    def _error(self, task, o: RunOutcome, j: int, where: dict) -> None:
        key = point_key(task)
        e = self.errors.setdefault(key, {"conditions": where, "count": 0})
        e.update(count=e["count"] + 1, status=int(o.status), status_name=Status(o.status).name, fault=o.fault,
                 run=_run_name(j), message=o.message, call=self.counts["calls"])

    # -- report ---------------------------------------------------------------------
    def summary(self) -> dict:
        """Plain dict (JSON-able) of the timeout in force, quarantined points, errors and counts.

        Returns
        -------
        dict
            ``timeout``: ``configured_s``, ``start_timeout_s``, ``multiple`` [-], ``floor_s``,
            ``in_force_s`` (the adaptive timeout now), ``median_healthy_s`` (None before any
            healthy run), ``healthy_runs``, ``changes`` (list of ``{call, timeout_s,
            median_healthy_s, healthy_runs}``, one per notable change, > 20 %);
            ``quarantine``: one dict per quarantined point: ``index`` (its position in the
            call where it failed), ``conditions`` (package units), ``status``,
            ``status_name``, ``fault`` ("crash", "timeout", "fatal"), ``run`` (which run failed),
            ``message``, ``p`` (parameters then), ``call``, ``timeout`` [s], ``faults``
            (simulations that faulted), ``skipped`` (calls that did not simulate it),
            ``retried``, ``retry_call``, ``retry_outcome`` (None, "failed again",
            "recovered"), ``active`` (still quarantined);
            ``errors``: points with an error status (fault "error": not quarantined; or
            "fatal": also quarantined): ``conditions``,
            ``count``, ``status``, ``status_name``, ``fault``, ``run``, ``message``, ``call``;
            ``counts``: ``calls``, ``points_simulated``, ``points_skipped``, ``crashes``,
            ``timeouts``, ``start_timeouts``, ``errors``, ``fatal`` (runs that met each),
            ``retries``;
            ``rules``: the quarantined fault kinds and the retry distance [parameter scales].
        """
        med = float(np.median(self.walls)) if self.walls else None
        r = self._rule
        return {
            "timeout": {"configured_s": r.configured, "start_timeout_s": r.start_timeout, "multiple": r.multiple,
                        "floor_s": r.floor, "in_force_s": self.timeout, "median_healthy_s": med,
                        "healthy_runs": self.n_healthy, "changes": list(self.changes)},
            "quarantine": [e.as_dict() for e in self.entries.values()],
            "errors": [dict(e) for e in self.errors.values()],
            "counts": dict(self.counts),
            "rules": {"quarantined_faults": list(QUARANTINE_FAULTS), "retry_distance_scales": self.retry_distance,
                      "retries_per_point": 1},
        }


def _conditions_text(conditions: dict) -> str:
    return "(" + ", ".join(f"{k} {v:g}" for k, v in conditions.items()) + ")"


def fault_sentences(summary: dict) -> dict[str, str]:
    """The report's lines of :meth:`FaultLedger.summary`: {label: text}.

    The simulations made and what they cost (:func:`calib.fmu.tally.tally_sentence`, when the summary
    has them) and the timeout in force (how it follows from the healthy runs); then, when any
    point faulted, the quarantined points and the points with an error status.
    """
    from calib.fmu.tally import tally_sentence
    t = summary["timeout"]
    med = t["median_healthy_s"]
    rule = (f"{t['multiple']:g}× the median healthy simulation ({med:.3g} s over {t['healthy_runs']} runs), at least "
            f"{t['floor_s']:g} s, at most the configured {t['configured_s']:g} s" if med is not None else
            f"the configured {t['configured_s']:g} s (no healthy simulation measured yet)")
    out = {"FMU simulations and their wall time": tally_sentence(summary["simulations"])} if "simulations" in summary else {}
    out["FMU simulation timeout"] = (f"{t['in_force_s']:.3g} s in force: {rule}; instantiation "
                                     f"{t['start_timeout_s']:g} s")
    quarantined = summary["quarantine"]
    if quarantined:
        out["FMU points quarantined"] = "; ".join(
            f"{_conditions_text(e['conditions'])} {e['status_name']} ({e['fault']} in the {e['run']}), simulated "
            f"{e['faults']}× and skipped {e['skipped']}×" + (f", retried: {e['retry_outcome']}" if e["retried"] else "")
            for e in quarantined)
    if summary["errors"]:
        out["FMU points with an error status"] = "; ".join(
            f"{_conditions_text(e['conditions'])} {e['status_name']} {e['count']}× ({e['message'][:80]})"
            for e in summary["errors"])
    return out
