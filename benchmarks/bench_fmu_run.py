"""``calib run`` through an FMU, phase by phase: the unit check, the calibration, the simulations.

The nearest equivalent this repository can build of a third-party steady-rotor FMU with an output
lag (issue 38): the bundled variant A (FMI 2.0, NREL 5-MW) with Øye dynamic inflow on (the lag:
induction filtered with a time constant of about a revolution) and rigid blades, no tower, shear
or gravity; the four scalar parameters of its mapping (three blade pitch offsets, the stall-delay
strength, Snel's model on); 48 operating points (12 wind speeds x 4 pitch angles); four channels
(power, thrust, root flap moment of blades 1 and 2); process executor, 2 workers. The
measurements are the FMU's own at a known truth plus 1 % Gaussian noise (with ``_sigma``
columns), written once into ``bench_output/fmu_run/``.

The workflow differentiates by forward differences with a step of 0.1 x each parameter's scale
(:data:`DIFFERENCES`, :data:`RELATIVE_STEP`; ``--differences central --relative-step 0.01`` gives the
mapping's default): measured at 4 560 -> 1 872 simulations, the estimate at the lowest cost of the three
schemes tried (CHANGELOG, issue 38 item 1d).

Printed, one line per phase: unit check [s], calibration [s], simulations (count), simulated
seconds (model time), busy worker seconds, wall [s], and the estimate with its σ.
``python benchmarks/bench_fmu_run.py [--out DIR] [--runs N] [--executor process|dask|both] [--differences
central|forward] [--relative-step H] [--settle-rtol R --settle-revolutions N]``; ``--settling`` runs only
:func:`settling_study` (settling, warm starts, the adaptive settle rule: CHANGELOG, issue 38); under ``make
validate`` :func:`run` (one run; several minutes of simulation on 2 workers: a study, not a ``make bench``
figure). ``--executor dask`` runs the same workflow on a Dask LocalCluster of 2 single-threaded worker
processes; ``both`` runs the process executor, then Dask, and says whether the estimates and their σ are
identical to the bit.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PARAMETERS = ["pitch_offset_blade1", "pitch_offset_blade2", "pitch_offset_blade3", "stall_delay_strength"]
TRUTH = [0.4, -0.3, 0.1, 1.5]
CHANNELS = ["power", "thrust", "root_flap_moment_blade1", "root_flap_moment_blade2"]
SWITCHES = dict(dynamic_inflow=True, flexible_blades=False, tower_shadow=False, shear=False, gravity=False,
                yaw=False, skewed_wake=False, stall_delay="snel")
STEADY = dict(steps_per_revolution=16, settle_revolutions=2, average_revolutions=2)
#: The measurements' window: 6 fixed settle revolutions (whatever the workflow's settling)
FIXED_6 = dict(steps_per_revolution=16, settle_revolutions=6, average_revolutions=2)
WIND = np.linspace(5.0, 16.0, 12)
PITCH = [0.0, 1.5, 3.0, 4.5]
RELATIVE_NOISE = 0.01
SEED = 38
#: The workflow's ``[model] jacobian`` (None: the mapping's, central at 0.01). Forward differences at a step
#: of 0.1 x scale: the difference study (``--difference-error``) finds their largest error 0.047 noise σ
#: against central at 0.2, nine times below the mapping's central at 0.01 (0.43: at that step the
#: Jacobian measures the FMU's output jumps, not its slope), at half the runs of a central Jacobian.
DIFFERENCES = "forward"
RELATIVE_STEP = 0.1
#: The workflow's ``[calibration] jacobian_updates`` (None: the default, ``auto``: Broyden's update for an FMU;
#: ``--jacobian-updates model`` gives a finite-difference Jacobian after every accepted step, as before).
JACOBIAN_UPDATES = None
#: A study of minutes: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"


def conditions():
    from calib.types import OperatingConditions
    v = np.repeat(WIND, len(PITCH))
    pitch = np.tile(PITCH, len(WIND))
    rpm = np.clip(7.0 + 0.45 * (v - 5.0) ** 1.2, 7.0, 12.1)
    return OperatingConditions(v, rpm, pitch, np.full(v.size, 1.225))


def _toml(value) -> str:
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    return repr(value)


def _jacobian() -> dict:
    """The workflow's ``[model] jacobian`` overrides (empty: the mapping's)."""
    return {k: v for k, v in (("differences", DIFFERENCES), ("relative_step", RELATIVE_STEP)) if v is not None}


def prepare(out: Path, executor: str = "process") -> Path:
    """The measurements (once) and the workflow file for ``executor`` (``process`` or ``dask``, 2 workers);
    returns the workflow's path."""
    out.mkdir(parents=True, exist_ok=True)
    table = out / "measurements.csv"
    if not table.is_file():
        from calib.fmu.build import build_fmu, mapping_path
        from calib.fmu.model import FmuModel
        from calib.measurements import synthesize
        model = FmuModel(build_fmu("A"), mapping_path("A"), CHANNELS, parameters=PARAMETERS, corrections=False,
                         switches=SWITCHES, steady=FIXED_6, isolate=False)
        meas = synthesize(model, np.array(TRUTH), conditions(), relative_sigma={c: RELATIVE_NOISE for c in CHANNELS},
                          channels=CHANNELS, seed=SEED, source="bench_fmu_run truth")
        meas.write_csv(table)
    wf = out / ("fmu_run.toml" if executor == "process" else f"fmu_run_{executor}.toml")
    wf.write_text("\n".join([
        'name = "bench_fmu_run"',
        'description = "issue 38 benchmark: a lagged steady rotor FMU, 4 parameters, 48 points, 4 channels"',
        "[rotor]", 'name = "nrel5mw"',
        "[model]", 'kind = "fmu"', 'variant = "A"', f"parameters = {_toml(PARAMETERS)}", "corrections = false",
        f"switches = {_toml(SWITCHES)}", f"steady = {_toml(STEADY)}",
        *([f"jacobian = {_toml(_jacobian())}"] if _jacobian() else []),
        "[grid]", "alpha_nodes_deg = [-10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0]",   # the FMU's default grid
        "eta_nodes = [0.2, 0.4, 0.6, 0.8, 1.0]",
        "[measurements]", f'file = "{table.name}"',
        *(["[calibration]", f'jacobian_updates = "{JACOBIAN_UPDATES}"'] if JACOBIAN_UPDATES else []),
        "[executor]", f'kind = "{executor}"', "workers = 2",
        "[[stages]]", 'name = "rotor_loads"', f"channels = {_toml(CHANNELS)}", ""]))
    return wf


def run_once(wf: Path, out: Path) -> dict:
    """One ``calib run`` in a fresh process; the phases from its console lines and its result."""
    calib = str(Path(sys.executable).with_name("calib"))
    t0 = time.perf_counter()
    proc = subprocess.run([calib, "run", str(wf), "--out", str(out), "--no-history"], capture_output=True,
                          text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if proc.returncode:
        raise RuntimeError(proc.stderr[-3000:] + proc.stdout[-3000:])
    text = proc.stdout + proc.stderr
    fig = {"wall_s": wall, "console": text}
    m = re.search(r"operating points, channels .*\(([\d.]+) s\)", text)
    fig["unit_check_s"] = float(m.group(1)) if m else float("nan")
    m = re.search(r"calibration ([\d.]+) s, figures ([\d.]+) s", text)
    fig["calibration_s"], fig["figures_s"] = (float(m.group(1)), float(m.group(2))) if m else (np.nan, np.nan)
    res = json.loads(next(out.glob("stage1_*/result.json")).read_text())
    with np.load(next(out.glob("stage1_*/result.npz"))) as z:
        fig["p_hat"], fig["sigma"] = z["estimate.p_hat"].tolist(), z["uncertainty.std_p"].tolist()
    fig["checks"] = res["provenance"]["checks"]
    fig.update(counts(res))
    return fig


def counts(res: dict) -> dict:
    """The MAP's counts from a ``result.json``: iterations, model Jacobians and evaluations, rejected trial
    steps, Broyden updates, final cost; the FMU simulations and model time of the calibration stage."""
    hist = res["estimate"].get("history", [])
    done = next((h for h in hist if h.get("stage") == "map_done"), {})
    failures = res["fit"]["failures"]
    out = {"map_iterations": done.get("iterations"), "rejected": done.get("rejected"),
           "broyden_updates": done.get("broyden_updates"), "final_cost": done.get("cost"),
           "map_status": done.get("status"), "model_jacobians": failures.get("model_jacobians"),
           "model_evaluations": failures.get("model_evaluations"),
           "accepted_steps": sum(1 for h in hist if h.get("stage") == "map" and "step" in h)}
    text = next((v for k, v in res["provenance"]["checks"].items() if k.startswith("FMU simulations and")), "")
    m = re.match(r"(\d+) simulations", text)
    out["simulations"] = int(m.group(1)) if m else None
    m = re.search(r"([\d.e+]+) s simulated", text)
    out["model_time_s"] = float(m.group(1)) if m else None
    return out


#: The difference schemes the study compares: (scheme, relative step), and its reference. The FMU's outputs jump
#: by about 0.014 noise σ at isolated parameter values (an inner iteration that stops one step earlier or later),
#: so a small step measures the jumps, not the slope: the reference is central at 0.2, checked against central
#: at 0.1 (they agree to 0.03 noise σ at the estimate).
SCHEMES = (("central", 0.01), ("forward", 0.01), ("central", 0.1), ("forward", 0.1))
REFERENCE = ("central", 0.2)


def difference_error(sigma_p, workers: int = 2) -> dict:
    """Error of each of :data:`SCHEMES` against :data:`REFERENCE` at the truth, as the error of a linearized
    prediction over one posterior σ of each parameter, in noise σ (1 %).

    Returns, per ``"scheme step"``, the largest, the 99th percentile and the median of
    ``|G - G_ref|[k, c, j] σ_j / σ_noise[k, c]`` over points, channels and parameters, and the largest per
    parameter; ``check`` is central at 0.1 against the reference (the reference's own error, roughly)."""
    from calib.executors import ProcessExecutor
    from calib.fmu.base_runs import BaseRunCache
    from calib.fmu.build import build_fmu, mapping_path
    from calib.fmu.model import FmuModel

    cond, p, cache = conditions(), np.array(TRUTH), BaseRunCache()
    with ProcessExecutor(workers) as ex:
        def jacobian(differences, step):
            m = FmuModel(build_fmu("A"), mapping_path("A"), CHANNELS, parameters=PARAMETERS, corrections=False,
                         switches=SWITCHES, steady=STEADY, jacobian=dict(differences=differences, relative_step=step),
                         executor=ex, base_runs=cache)
            try:
                return m.jacobian(p, cond)
            finally:
                m.close()
        ev, G_ref = jacobian(*REFERENCE)
        found = {k: jacobian(*k)[1] for k in SCHEMES}
    noise = RELATIVE_NOISE * np.abs(ev.values)

    def error(G):
        e = np.abs(G - G_ref) * np.asarray(sigma_p)[None, None, :] / noise[:, :, None]
        return {"max": float(np.nanmax(e)), "p99": float(np.nanpercentile(e, 99)), "median": float(np.nanmedian(e)),
                "max_per_parameter": np.nanmax(e, axis=(0, 1)).tolist()}
    out = {f"{k[0]} {k[1]:g}": error(G) for k, G in found.items()}
    out["check"] = error(found[("central", 0.1)])
    return out


#: The posterior σ of the bench's estimate (CHANGELOG, issue 38: forward 0.1, Broyden), for the settling study's
#: Jacobian error in noise σ
SIGMA_P = (0.02071, 0.02304, 0.08896, 0.11253)


def settling_study(long_revolutions: int = 24, warm_revolutions: int = 6) -> dict:
    """Where a run's simulated time goes and what settling buys, at the bench's 48 points and the truth, in process.

    Per point, cold runs (base and the 4 forward perturbations at 0.1 x scale) of ``long_revolutions``
    revolutions give per-revolution means; the last two revolutions are the reference (settled). From them:
    the level error of a window of ``s`` settle + 2 average revolutions; the error of a forward-difference
    Jacobian made of such windows (a 1-σ linearized prediction, in noise σ, as :func:`difference_error`);
    the adaptive rule (``[steady] settle_rtol``: stop at the first window whose halves agree to it). Warm
    starts: the perturbed runs restored from the base run's state after 2 settle revolutions, settle ``s``,
    average 2, differenced against the base run continued from the same state. And the CPU split of one run
    (instantiation, stepping, output handling). Noise σ = 1 % of the settled value.
    """
    from calib.fmu.build import build_fmu, mapping_path
    from calib.fmu.model import FmuModel
    from calib.fmu.simulator import Simulator

    m = FmuModel(build_fmu("A"), mapping_path("A"), CHANNELS, parameters=PARAMETERS, corrections=False,
                 switches=SWITCHES, steady=STEADY, isolate=False,
                 jacobian=dict(differences="forward", relative_step=RELATIVE_STEP))
    _, tasks, steps = m._tasks(np.array(TRUTH), conditions(), True)
    plan = m._plan
    n = plan.steady.steps_per_revolution
    col = [s.index for s in plan.signals if s.name in CHANNELS]
    sim = Simulator(plan)
    cpu = {"instantiation": 0.0, "stepping": 0.0, "outputs": 0.0}

    def revolutions(task, params, count, state=None, t0=0.0):
        h, _, _ = plan.steady.window(task.rotor_speed)
        c0 = time.process_time()
        if state is None:
            sim._fresh()
            sim._set(plan.fixed), sim._set(params), sim._set(task.inputs)
            sim._initialize(0.0), sim._exit_initialization()
        else:
            sim.set_state(state)
            sim._set(params)
        c1 = time.process_time()
        raw, _, _, t = sim._window(t0, h, 0, count * n)
        c2 = time.process_time()
        out = raw[:, col].reshape(count, n, -1).mean(axis=1)
        cpu["instantiation"] += c1 - c0
        cpu["stepping"] += c2 - c1
        cpu["outputs"] += time.process_time() - c2
        return out, t

    base, pert, cont, warm = [], [], [], []
    for t in tasks:
        base.append(revolutions(t, t.base, long_revolutions)[0])
        pert.append([revolutions(t, q, long_revolutions)[0] for q in t.perturbations])
        h, _, _ = plan.steady.window(t.rotor_speed)
        sim._fresh()
        sim._set(plan.fixed), sim._set(t.base), sim._set(t.inputs)
        sim._initialize(0.0), sim._exit_initialization()
        _, _, _, ts = sim._window(0.0, h, 2 * n, 0)
        state = sim.get_state()
        cont.append(revolutions(t, t.base, warm_revolutions, state, ts)[0])
        warm.append([revolutions(t, q, warm_revolutions, state, ts)[0] for q in t.perturbations])
        sim.free_state(state)
    sim.close()
    base, pert, cont, warm = map(np.array, (base, pert, cont, warm))
    return {"cpu_s": cpu, "runs": len(tasks) * (1 + len(steps)) * 2, **settling_figures(base, pert, cont, warm, steps)}


def settling_figures(base, pert, cont, warm, steps, A: int = 2) -> dict:
    """The figures of :func:`settling_study` from its per-revolution means: ``base`` (points, revolutions,
    channels) and ``pert`` (points, parameters, revolutions, channels) of cold runs, ``cont`` and ``warm`` the same
    for the base run continued and the perturbed runs restored from its settled state; ``steps`` the forward
    steps [package units]."""
    warm_revolutions = cont.shape[1]
    settled = base[:, -A:].mean(1)
    noise = RELATIVE_NOISE * np.abs(settled)
    G_ref = (pert[:, :, -A:].mean(2) - settled[:, None]) / steps[None, :, None]
    sig = np.asarray(SIGMA_P)

    def jac_error(G):
        e = np.abs(G - G_ref) * sig[None, :, None] / noise[:, None, :]
        return {"max": float(e.max()), "p99": float(np.percentile(e, 99)), "median": float(np.median(e)),
                "max_per_parameter": e.max(axis=(0, 2)).tolist()}

    def level(x):
        e = np.abs(x - settled) / noise
        return {"max": float(e.max()), "median": float(np.median(e))}

    out = {"reference_drift": level(base[:, -2 * A:-A].mean(1)), "cold": {}, "warm": {}, "adaptive": {}}
    for s in range(5):
        out["cold"][s] = {"level": level(base[:, s:s + A].mean(1)),
                          "jacobian": jac_error((pert[:, :, s:s + A].mean(2) - base[:, s:s + A].mean(1)[:, None])
                                                / steps[None, :, None])}
        if s + A <= warm_revolutions:
            out["warm"][s] = {"jacobian": jac_error((warm[:, :, s:s + A].mean(2) - cont[:, s:s + A].mean(1)[:, None])
                                                    / steps[None, :, None])}

    def stop(x, tol, most):   # the simulator's rule on per-revolution means: halves of the 2-revolution window
        for s in range(most + 1):
            w = x[s:s + A]
            if np.all(np.abs(w[1] - w[0]) <= tol * np.abs(w.mean(0))):
                return s
        return most
    for most in (2, 12):
        for tol in (1e-3, 7e-4, 5e-4, 3e-4, 1e-4):
            S = np.array([stop(x, tol, most) for x in base])
            SP = np.array([[stop(x, tol, most) for x in row] for row in pert])
            lev = np.array([x[s:s + A].mean(0) for x, s in zip(base, S)])
            G = np.array([[(pert[k, j, SP[k, j]:SP[k, j] + A].mean(0) - lev[k]) / steps[j] for j in range(len(steps))]
                          for k in range(len(base))])
            out["adaptive"][f"{tol:g} at most {most}"] = {
                "revolutions_per_run": float(A + (S.sum() + SP.sum()) / (S.size + SP.size)),
                "level": level(lev), "jacobian": jac_error(G)}
    return out


def run(out: Path | None = None) -> dict:
    """One ``calib run`` of the benchmark (benchmarks/run_all.py): its phases' seconds, the FMU simulation
    counts the result states, the estimate and its σ."""
    out = Path(out or ROOT / "bench_output" / "fmu_run")
    fig = run_once(prepare(out), out / "run1")
    return {k: v for k, v in fig.items() if k != "console"}


def main(argv=None) -> int:
    global DIFFERENCES, RELATIVE_STEP, JACOBIAN_UPDATES
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(ROOT / "bench_output" / "fmu_run"))
    ap.add_argument("--runs", type=int, default=1)
    ap.add_argument("--difference-error", nargs=4, type=float, metavar="SIGMA",
                    help="only measure the finite-difference error against the posterior σ of the 4 parameters")
    ap.add_argument("--differences", choices=("central", "forward"), default=DIFFERENCES,
                    help=f"the [model] jacobian.differences of the workflow (default {DIFFERENCES}; the mapping's: "
                         "central)")
    ap.add_argument("--relative-step", type=float, default=RELATIVE_STEP,
                    help=f"the [model] jacobian.relative_step of the workflow (default {RELATIVE_STEP:g}; the "
                         "mapping's: 0.01)")
    ap.add_argument("--jacobian-updates", choices=("auto", "broyden", "model"), default=JACOBIAN_UPDATES,
                    help="the [calibration] jacobian_updates of the workflow (default: the settings' auto)")
    ap.add_argument("--settle-rtol", type=float, default=None,
                    help="the workflow's [model] steady.settle_rtol: settle each run until its window's halves agree "
                         "to this (default: fixed settling)")
    ap.add_argument("--settle-revolutions", type=int, default=STEADY["settle_revolutions"],
                    help="the workflow's steady.settle_revolutions (with --settle-rtol: the most)")
    ap.add_argument("--settling", action="store_true",
                    help="only the settling and warm-start study at the 48 points (in process, one core, minutes)")
    ap.add_argument("--executor", choices=("process", "dask", "both"), default="process",
                    help="2 worker processes, a Dask LocalCluster of 2 workers, or both (estimates compared)")
    args = ap.parse_args(argv)
    if args.difference_error:
        for scheme, e in difference_error(args.difference_error).items():
            print(f"[bench_fmu_run] {scheme}: error of a 1-σ linearized prediction / noise against central "
                  f"{REFERENCE[1]:g}: max {e['max']:.2e}, p99 {e['p99']:.2e}, median {e['median']:.2e}, per parameter "
                  f"max {np.round(e['max_per_parameter'], 3).tolist()}")
        return 0
    if args.settling:
        study = settling_study()
        print(json.dumps(study, indent=1))
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / "settling.json").write_text(json.dumps(study, indent=1))
        return 0
    DIFFERENCES, RELATIVE_STEP, JACOBIAN_UPDATES = args.differences, args.relative_step, args.jacobian_updates
    STEADY["settle_revolutions"] = args.settle_revolutions
    if args.settle_rtol is not None:
        STEADY["settle_rtol"] = args.settle_rtol
    out = Path(args.out)
    kinds = ("process", "dask") if args.executor == "both" else (args.executor,)
    estimates = {}
    for kind, k in ((kind, k) for kind in kinds for k in range(args.runs)):
        wf = prepare(out, kind)
        fig = run_once(wf, out / (f"run{k + 1}" if kind == "process" else f"run{k + 1}_{kind}"))
        estimates.setdefault(kind, (fig["p_hat"], fig["sigma"]))
        print(f"[bench_fmu_run] executor       {kind}")
        print(f"[bench_fmu_run] unit check     {fig['unit_check_s']:7.1f} s")
        print(f"[bench_fmu_run] calibration    {fig['calibration_s']:7.1f} s (figures {fig['figures_s']:.1f} s)")
        for label, text in fig["checks"].items():
            if label.startswith("FMU simulations and"):
                print(f"[bench_fmu_run] {label}: {text}")
        print(f"[bench_fmu_run] wall           {fig['wall_s']:7.1f} s")
        print("[bench_fmu_run] counts " + ", ".join(f"{k} {fig[k]}" for k in (
            "map_status", "map_iterations", "accepted_steps", "model_jacobians", "model_evaluations", "rejected",
            "broyden_updates", "simulations", "model_time_s", "final_cost")))
        print(f"[bench_fmu_run] p_hat {np.round(fig['p_hat'], 5).tolist()} sigma {np.round(fig['sigma'], 5).tolist()}")
        run_dir = out / (f"run{k + 1}" if kind == "process" else f"run{k + 1}_{kind}")
        (run_dir / "bench.json").write_text(json.dumps({name: v for name, v in fig.items() if name != "console"},
                                                       indent=1))
        (run_dir / "console.txt").write_text(fig["console"])
    if len(estimates) == 2:
        same = all(np.array_equal(a, b) for a, b in zip(estimates["process"], estimates["dask"]))
        print(f"[bench_fmu_run] process and dask: estimate and sigma {'identical to the bit' if same else 'DIFFER'}")
        return 0 if same else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
