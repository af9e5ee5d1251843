"""Where one FMU simulation's time goes (issue 38): the FMU's own stepping against everything around it.

The simulations of :mod:`bench_fmu_run` (bundled variant A, FMI 2.0, Øye dynamic inflow, 4 parameters, 16
communication steps per revolution, 2 settle + 2 average revolutions = 64 steps) at its 48 operating points and
its truth, measured three ways, CPU seconds (``time.process_time``) unless said otherwise:

1. **fmpy alone** (:func:`fmpy_split`): the FMI calls of one cold run, each timed: load the library and create
   the instance (``FMU2Slave`` + ``instantiate``), ``reset``, the setters, ``setupExperiment`` +
   ``enterInitializationMode`` + ``exitInitializationMode``, ``doStep`` x 64, ``getReal`` x 32, ``terminate``
   + ``freeInstance``; and ``fmi2DoStep`` in a tight ctypes loop (the physical limit: the FMU's own cost of a
   communication step, no Python wrapper around it), per internal step of the FMU (:func:`internal_steps`: it
   integrates at most ``max_internal_step`` = 0.02 s and 2° of azimuth per internal step, each a BEM solve of
   every blade element).
2. **calib's simulator in process** (:func:`simulator_split`): the runs of a forward-difference Jacobian (a cold
   base run that keeps its settled state, 4 warm perturbed runs restored from it) through
   :meth:`calib.fmu.simulator.Simulator.runs`, with the FMI stepping, the output reads, the state calls
   (get / set / serialize) and the rest (setters, initialization, the window statistics and status: calib's own
   output handling) timed apart.
3. **Through the worker processes** (:func:`pipeline_split`): the same Jacobian at the 48 points on the process
   executor with 2 workers, isolated FMU processes (what ``calib run`` does): the CPU of every process below
   the benchmark (executor workers and FMU processes, ``RUSAGE_CHILDREN`` after the pool is closed) against the
   in-process cost of the same simulations: the difference is the inter-process cost (pickling, pipes, process
   start, instance creation in each FMU process), split between the FMU processes and the pool workers that
   relay their tasks.

:func:`floor`: the wall of ``calib run`` if only the FMU's stepping took time (its simulations x the stepping of
one / 2 workers), and how many such simulations fit in the issue's 20 s.

``python benchmarks/bench_fmu_cost.py [--repeats N]`` prints the split and publishes it
(``docs/validation/data/fmu_cost.json``, the speed page's section "Through an FMU"): CPU seconds, which a loaded
machine inflates by a few per cent only, with the load average beside them. Under ``make validate`` :func:`run`.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_fmu_run  # noqa: E402

#: A study of a minute of CPU on 2 workers (``make validate``), not a ``make bench`` figure.
SUITE = "validate"
ROOT = HERE.parent
#: Simulations of ``calib run`` of :mod:`bench_fmu_run` at 12c1033 (CHANGELOG, issue 38): the floor's count, the
#: unit check's 48 and the calibration's 1 152 (its result's count; 192 more base runs reused, not simulated)
BENCH_SIMULATIONS = 48 + 1152


def _model(isolate: bool, executor=None):
    from calib.fmu.build import build_fmu, mapping_path
    from calib.fmu.model import FmuModel
    return FmuModel(build_fmu("A"), mapping_path("A"), bench_fmu_run.CHANNELS, parameters=bench_fmu_run.PARAMETERS,
                    corrections=False, switches=bench_fmu_run.SWITCHES, steady=bench_fmu_run.STEADY, isolate=isolate,
                    executor=executor, jacobian=dict(differences="forward", relative_step=bench_fmu_run.RELATIVE_STEP))


def _tasks():
    m = _model(isolate=False)
    _, tasks, _ = m._tasks(np.array(bench_fmu_run.TRUTH), bench_fmu_run.conditions(), True)
    plan = m._plan
    m.close()
    return plan, tasks


class _Clock:
    """CPU seconds [s] and calls per label."""

    def __init__(self):
        self.cpu, self.calls = {}, {}

    def timed(self, label, fn):
        def wrapped(*args, **kwargs):
            c0 = time.process_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.cpu[label] = self.cpu.get(label, 0.0) + time.process_time() - c0
                self.calls[label] = self.calls.get(label, 0) + 1
        return wrapped


def fmpy_split(plan, tasks, repeats: int = 3) -> dict:
    """The FMI calls of one cold run of 64 steps through fmpy, per call [ms], mean over ``repeats`` runs at each of
    4 of the points (the slowest and fastest rotor speeds among them); and ``fmi2DoStep`` in a tight ctypes loop
    [ms per communication step]."""
    from fmpy.fmi2 import FMU2Slave
    clock = _Clock()
    picked = [tasks[0], tasks[15], tasks[31], tasks[47]]
    steps = 0
    for task in picked * repeats:
        h, n_settle, n_average = plan.steady.window(task.rotor_speed)
        fmu = clock.timed("load + instantiate", lambda: _instantiate(FMU2Slave, plan))()
        clock.timed("set (fixed, parameters, inputs)", lambda: _set_all(fmu, plan, task))()
        clock.timed("setupExperiment + enter/exitInitializationMode", lambda: _init(fmu))()
        step = clock.timed("doStep", fmu.doStep)
        get = clock.timed("getReal", fmu.getReal)
        t = 0.0
        for k in range(n_settle + n_average):
            step(currentCommunicationPoint=t, communicationStepSize=h)
            t += h
            if k >= n_settle:
                get(list(plan.read_vrs))
        steps += n_settle + n_average
        clock.timed("reset", fmu.reset)()
        clock.timed("terminate + freeInstance", lambda: (fmu.terminate(), fmu.freeInstance()))()
    runs = len(picked) * repeats
    per_run = {k: 1e3 * v / runs for k, v in clock.cpu.items()}
    per_run["doStep per step"] = 1e3 * clock.cpu["doStep"] / steps
    fmu = _instantiate(FMU2Slave, plan)
    task = tasks[24]
    h, _, _ = plan.steady.window(task.rotor_speed)
    _set_all(fmu, plan, task)
    _init(fmu)
    n, t = 640, 0.0
    c0 = time.process_time()
    for _ in range(n):
        fmu.fmi2DoStep(fmu.component, t, h, 1)
        t += h
    per_run["fmi2DoStep per step, tight ctypes loop"] = 1e3 * (time.process_time() - c0) / n
    fmu.terminate()
    fmu.freeInstance()
    inner = internal_steps(plan, tasks)
    per_step = per_run["fmi2DoStep per step, tight ctypes loop"] / inner["per_communication_step"][24]
    return {"ms_per_run": per_run, "runs": runs, "steps_per_run": steps / runs,
            "internal_steps_per_simulation": float(np.mean(inner["per_simulation"])),
            "internal_step_s": inner["max_step_s"], "us_per_internal_step": 1e3 * per_step}


def internal_steps(plan, tasks) -> dict:
    """The FMU's internal steps (its ``core_do_step``: ``ceil(h / min(max_internal_step, max_azimuth_step / Ω))``
    per communication step of ``h`` seconds, the two limits read from its model description) per communication
    step and per simulation of the window, at each point."""
    from fmpy import read_model_description
    start = {v.name: float(v.start) for v in read_model_description(plan.unzip_dir).modelVariables
             if v.name in ("max_internal_step", "max_azimuth_step")}
    per_step, per_sim = [], []
    for task in tasks:
        h, n_settle, n_average = plan.steady.window(task.rotor_speed)
        omega = task.rotor_speed * np.pi / 30.0
        dt_max = min(start["max_internal_step"], np.radians(start["max_azimuth_step"]) / omega)
        n = max(1, int(np.ceil(h / dt_max - 1e-9)))
        per_step.append(n)
        per_sim.append(n * (n_settle + n_average))
    return {"per_communication_step": per_step, "per_simulation": per_sim, "max_step_s": start["max_internal_step"]}


def _instantiate(cls, plan):
    fmu = cls(guid=plan.guid, unzipDirectory=plan.unzip_dir, modelIdentifier=plan.model_identifier,
              instanceName="bench")
    fmu.instantiate()
    return fmu


def _set_all(fmu, plan, task):
    for group in (plan.fixed, task.base, task.inputs):
        for a in group:
            if a.type == "real":
                fmu.setReal(list(a.vrs), list(a.values))
            elif a.type == "integer":
                fmu.setInteger(list(a.vrs), [int(v) for v in a.values])
            else:
                fmu.setBoolean(list(a.vrs), [bool(v) for v in a.values])


def _init(fmu):
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()


def simulator_split(plan, tasks) -> dict:
    """The runs of a forward-difference Jacobian at every point through :meth:`Simulator.runs` in this process,
    CPU [ms per simulation]: FMI stepping, output reads, state calls, and the rest (calib's own handling)."""
    from calib.fmu.simulator import Simulator
    sim = Simulator(plan)
    clock = _Clock()
    sim._step = clock.timed("doStep", sim._step)
    sim._read = clock.timed("getReal (one ctypes call per step)", sim._read)
    for name in ("get_state", "set_state", "serialize", "deserialize", "free_state"):
        setattr(sim, name, clock.timed("FMU state get/set/serialize/free", getattr(sim, name)))
    sim._instantiate = clock.timed("instantiation", sim._instantiate)
    runs, total = 0, 0.0
    for task in tasks:
        c0 = time.process_time()
        for msg in sim.runs(task):
            runs += 1
            assert msg[1 if msg[0] == "base" else 2].ok, msg
        total += time.process_time() - c0
    sim.close()
    out = {k: 1e3 * v / runs for k, v in clock.cpu.items()}
    out["everything else (setters, initialization, window statistics, status)"] = \
        1e3 * total / runs - sum(out.values())
    out["total"] = 1e3 * total / runs
    return {"ms_per_simulation": out, "simulations": runs,
            "steps": int(clock.calls["doStep"]), "steps_per_simulation": clock.calls["doStep"] / runs}


def _process_cpu(pid: int) -> float:
    """CPU seconds (user + system) of the live process ``pid`` (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _worker_cpu(_=None) -> dict:
    """Executor task: this pool worker's pid and CPU [s], and the CPU [s] of the FMU processes it supervises."""
    from calib.fmu import worker as fw
    time.sleep(0.5)                         # long enough for each pool worker to take one of these tasks
    fmu = {w.proc.pid: _process_cpu(w.proc.pid) for w in fw._WORKERS.values()
           if isinstance(w, fw.WorkerProcess) and w.proc is not None}
    return {"pid": os.getpid(), "cpu": time.process_time(), "fmu": fmu}


def pipeline_split(plan_tasks_cost_ms: float, workers: int = 2) -> dict:
    """The Jacobian at the 48 points through the process executor (``workers`` workers, isolated FMU processes):
    CPU of the FMU processes and of the pool workers that relay their tasks [s] and per simulation [ms]
    (``/proc``, read by a task on each pool worker before it closes), of all processes below this one
    (``RUSAGE_CHILDREN``, after the pool closed), the wall [s], against ``plan_tasks_cost_ms`` (the in-process
    cost of a simulation, :func:`simulator_split`)."""
    from calib.executors import ProcessExecutor
    from calib.fmu.worker import close_workers
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    load0 = os.getloadavg()[0]
    w0 = time.perf_counter()
    with ProcessExecutor(workers) as ex:
        m = _model(isolate=True, executor=ex)
        ev, G = m.jacobian(np.array(bench_fmu_run.TRUTH), bench_fmu_run.conditions())
        summary = m.simulation_summary()
        wall = time.perf_counter() - w0
        seen = {r["pid"]: r for r in ex.map(_worker_cpu, range(workers))}
        m.close()
    close_workers()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    sims = int(summary["simulations"])
    fmu_cpu = sum(c for r in seen.values() for c in r["fmu"].values())
    out = {"simulations": sims, "children_cpu_s": cpu, "cpu_ms_per_simulation": 1e3 * cpu / sims,
           "in_process_ms_per_simulation": plan_tasks_cost_ms,
           "inter_process_ms_per_simulation": 1e3 * cpu / sims - plan_tasks_cost_ms,
           "busy_worker_s": summary["busy_worker_s"], "wall_s": wall, "load_before": load0,
           "load_after": os.getloadavg()[0], "all_converged": bool(np.all(ev.status == 0))}
    if len(seen) == workers:                # every pool worker answered: the split is whole
        out.update({"fmu_process_cpu_s": fmu_cpu, "fmu_process_ms_per_simulation": 1e3 * fmu_cpu / sims,
                    "pool_worker_cpu_s": sum(r["cpu"] for r in seen.values()),
                    "pool_worker_ms_per_simulation": 1e3 * sum(r["cpu"] for r in seen.values()) / sims})
    return out


def run(repeats: int = 3) -> dict:
    """All three splits (benchmarks/run_all.py)."""
    plan, tasks = _tasks()
    out = {"fmpy": fmpy_split(plan, tasks, repeats), "simulator": simulator_split(plan, tasks)}
    out["pipeline"] = pipeline_split(out["simulator"]["ms_per_simulation"]["total"])
    out["floor"] = floor(out)
    from publish import command_line, publish
    out["published"] = publish("fmu_cost", out, command_line(), _markdown(out))
    return out


def _markdown(out: dict) -> str:
    """The split of one simulation's CPU and the floor, as the speed page shows them."""
    sim, fmpy, pipe, fl = (out[k] for k in ("simulator", "fmpy", "pipeline", "floor"))
    ms, steps = sim["ms_per_simulation"], fmpy["steps_per_run"]
    tight = fmpy["ms_per_run"]["fmi2DoStep per step, tight ctypes loop"] * steps
    rows = [("the FMU's stepping: every `doStep` of the run, through calib's simulator", ms["doStep"]),
            ("the same steps in a tight ctypes loop: the FMU's own cost", tight),
            ("reading the outputs", ms["getReal (one ctypes call per step)"]),
            ("calib's own: setters, initialization, window statistics, status",
             ms["everything else (setters, initialization, window statistics, status)"]),
            ("instantiation (once per worker, then `reset`)", ms["instantiation"]),
            ("between processes: pipes, pickling, the pool workers' relay", pipe["inter_process_ms_per_simulation"])]
    lines = ["| part of one simulation | CPU ms |", "|---|---|"]
    lines += [f"| {what} | {v:.3g} |" for what, v in rows]
    lines += ["", f"One simulation is {steps:.0f} communication steps; the FMU integrates {fmpy['internal_steps_per_simulation']:.0f} "
              f"internal steps of at most {fmpy['internal_step_s']} s in them, {fmpy['us_per_internal_step']:.1f} µs each "
              f"(a BEM solve of every blade element). The FMU's stepping is "
              f"{100 * ms['doStep'] / ms['total']:.1f} % of a simulation in process. **The floor of `calib run`** if "
              f"nothing but the FMU's stepping took time: {fl['simulations']} simulations x {fl['stepping_ms_per_simulation']:.1f} ms "
              f"/ 2 workers = **{fl['wall_floor_s']:.1f} s**; the issue's 20 s holds {fl['simulations_in_20_s']} such "
              f"simulations. Load average {pipe['load_before']:.1f} before and {pipe['load_after']:.1f} after the "
              f"pipeline's {pipe['simulations']} simulations."]
    return "\n".join(lines) + "\n"


def floor(out: dict, simulations: int = BENCH_SIMULATIONS, workers: int = 2) -> dict:
    """The wall clock of ``calib run`` [s] if nothing but the FMU's stepping cost time: ``simulations`` x the
    stepping of one simulation (:func:`simulator_split`) / ``workers``; and the simulations of that cost that fit
    in the issue's 20 s."""
    step_ms = out["simulator"]["ms_per_simulation"]["doStep"]
    return {"simulations": simulations, "stepping_ms_per_simulation": step_ms,
            "stepping_cpu_s": simulations * step_ms / 1e3, "wall_floor_s": simulations * step_ms / 1e3 / workers,
            "simulations_in_20_s": int(20.0 * workers / (step_ms / 1e3))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="cold runs per picked point in the fmpy split")
    args = ap.parse_args(argv)
    out = run(args.repeats)
    for part in ("fmpy", "simulator"):
        for k, v in next(v for k, v in out[part].items() if k.startswith("ms_per")).items():
            print(f"[bench_fmu_cost] {part:9s} {k:70s} {v:9.3f} ms")
    for part in ("pipeline", "floor"):
        for k, v in out[part].items():
            print(f"[bench_fmu_cost] {part:9s} {k:70s} {v}")
    for k in ("internal_steps_per_simulation", "internal_step_s", "us_per_internal_step"):
        print(f"[bench_fmu_cost] fmpy      {k:70s} {out['fmpy'][k]}")
    print(f"[bench_fmu_cost] wrote {out['published']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
