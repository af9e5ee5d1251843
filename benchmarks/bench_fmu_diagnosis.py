"""The diagnosis on the bundled FMUs (issue 25, item 5): the same rules, an unsteady truth.

Truth: the bundled rotor FMU (variants A, FMI 2.0, SI, and B, FMI 3.0, kW/kN and rad/s:
each read through its own mapping) on the NREL 5-MW with the periodic physics on (tower
shadow, wind shear, Øye dynamic inflow) and Du & Selig's stall delay at strength 1,
simulated at 72 steps per revolution and averaged over 4 whole revolutions after 10
settling ones (with 3, and with 6 and a pitched blade, the dynamic inflow is still settling
at λ 9-11 and the FMU reports those points not steady); 10 operating points (λ 3, 5, 7, 9,
11 × pitch 0 and 4 deg at 10 rpm: the low λ stall the inboard blade, where a stall delay
shows), power, thrust and blade-1 root flap
moment, 1 % noise. The diagnosis runs
``calib diagnose`` with the same FMU configured as a user would for speed: 24 steps per
revolution, 4 settling and 2 averaged revolutions, and a 2 × 2 correction grid; so the model
never reproduces its truth exactly (time discretization, averaging windows, the transient left
after settling): out of family by construction. The calibrations use a fixed truncation
(σ̄ = 0.5) and at most 3 re-linearizations of 10 iterations: with the automatic truncation one
localization on this FMU made 23 Jacobians (10 s each) in its first 4 minutes, which puts a
diagnosis beyond what a benchmark can repeat. Candidates: the mapped pitch offsets of blades 1
and 2 and the stall-delay strength.

Data sets (the truth's mapped parameters): ``control`` (nominal), ``pitch_offset_blade1``
(+1 deg on blade 1), ``stall_delay_strength`` (1.8 instead of 1). Right: ``none`` on the
control, the data set's parameter (or ``ambiguous`` with it) on the others.

``python benchmarks/bench_fmu_diagnosis.py [n_seeds [process|dask]]`` (default 1, process; ``dask``
runs the same diagnoses on a Dask LocalCluster of 2 workers and publishes nothing);
``python benchmarks/bench_fmu_diagnosis.py case [VARIANT DATA_SET SEED EXECUTOR [OUT.json]]`` runs one
diagnosis with its simulations counted at every step (:func:`case`). Under ``make validate``
``run(n_seeds=1)``: 47.6 min on the shared 2-core machine (2026-11-25; 2-3 min per control,
7-15 min per named effect), every verdict right, variant B's figures equal to A's. Writes ``bench_output/fmu_diagnosis.json`` and ``.md`` and publishes the table for the validation page
(``docs/validation/data/diagnosis_fmu.json``); two worker
processes per diagnosis. Each diagnosis also states its FMU simulations (count, model time simulated, busy
worker seconds: :func:`calib.fmu.tally.process_totals`), the figure to compare across machines.
"""

from __future__ import annotations

import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT_JSON = ROOT / "bench_output" / "fmu_diagnosis.json"
OUT_MD = ROOT / "bench_output" / "fmu_diagnosis.md"
WORK = ROOT / "bench_output" / "fmu_diagnosis"

#: A statistical study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

CHANNELS = ["power", "thrust", "root_flap_moment"]
SWITCHES = {"tower_shadow": True, "shear": True, "yaw": False, "flexible_blades": False, "gravity": False,
            "skewed_wake": False, "dynamic_inflow": True, "tip_loss": True, "hub_loss": True, "stall_delay": "du_selig"}
TRUTH_STEADY = {"steps_per_revolution": 72, "settle_revolutions": 10, "average_revolutions": 4}
MODEL_STEADY = {"steps_per_revolution": 24, "settle_revolutions": 4, "average_revolutions": 2}
CANDIDATES = ["pitch_offset_blade1", "pitch_offset_blade2", "stall_delay_strength"]
DATA_SETS = {"control": {}, "pitch_offset_blade1": {"pitch_offset_blade1": 1.0},
             "stall_delay_strength": {"stall_delay_strength": 1.8}}
SEED0 = 9700


def _inline(table: dict) -> str:
    return "{ " + ", ".join(f"{k} = {json.dumps(v)}" for k, v in table.items()) + " }"


def config_text(variant: str, executor: str = "process", jacobian: dict | None = None) -> str:
    """The ``calib diagnose`` config of the model (the user's faster FMU configuration), its
    simulations on ``executor`` (``process`` or ``dask``: a LocalCluster) with 2 workers;
    ``jacobian``: overrides of the mapping's ``[jacobian]`` (default none: the mapping's)."""
    return f"""[rotor]
name = "nrel5mw"

[model]
kind = "fmu"
variant = "{variant}"
switches = {_inline(SWITCHES)}
steady = {_inline(MODEL_STEADY)}
{"" if not jacobian else "jacobian = " + _inline(jacobian)}

[grid]
alpha_nodes_deg = [0.0, 10.0]
eta_nodes = [0.6, 1.0]

[calibration]
noise = "known"
sigma_bar = 0.5
max_relinearizations = 3
max_iterations = 10

[diagnosis]
candidates = {json.dumps(CANDIDATES)}
max_effects = 1
recalibrate = false

[executor]
kind = "{executor}"
workers = 2
"""


def conditions():
    from calib.rotor.library import load_rotor
    from calib.types import OperatingConditions
    rotor = load_rotor("nrel5mw")
    T, P = np.meshgrid([3.0, 5.0, 7.0, 9.0, 11.0], [0.0, 4.0], indexing="ij")
    v = 10.0 * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, 10.0), P.ravel())


def truth_values(variant: str, values: dict, folder: Path):
    """The truth FMU's steady outputs at the campaign, shape (10, 3) [SI]."""
    from calib.corrections import CorrectionGrid
    from calib.models.from_config import model_from_workflow
    names = list(values)
    model = model_from_workflow({"kind": "fmu", "variant": variant, "switches": SWITCHES, "steady": TRUTH_STEADY,
                                 "parameters": names or ["pitch_offset_blade1"], "corrections": False},
                                {"name": "nrel5mw"}, CHANNELS, str(folder / "truth.toml"), folder,
                                grid=CorrectionGrid([0.0, 10.0], [0.6, 1.0]))
    try:
        p = np.array([values[n] for n in names] if names else [0.0])
        ev = model.evaluate(p, conditions())
    finally:
        model.close()
    if ev.n_failed:
        raise RuntimeError(f"the truth FMU failed: {ev.failure_summary()}")
    return ev.values


def run(n_seeds: int = 1, variants=("A", "B"), executor: str = "process") -> dict:
    """Diagnose every data set of both variants on ``n_seeds`` noise seeds; returns the figures.

    ``executor``: ``process`` (published) or ``dask`` (a Dask LocalCluster of 2 workers; its figures
    go to ``bench_output/fmu_diagnosis_dask.*`` and are not published)."""
    from calib.diagnosis.command import run_diagnose
    from calib.fmu.tally import process_totals
    t_start = time.perf_counter()
    WORK.mkdir(parents=True, exist_ok=True)
    rows, verdicts = [], []
    for variant in variants:
        config = WORK / f"config_{variant}{'' if executor == 'process' else '_' + executor}.toml"
        config.write_text(config_text(variant, executor))
        for name, values in DATA_SETS.items():
            t0 = time.perf_counter()
            clean = truth_values(variant, values, WORK)
            truth_seconds = time.perf_counter() - t0
            named, seconds, sims = [], [], []
            for k in range(n_seeds):
                data = noisy_table(variant, name, clean, k)
                t1 = time.perf_counter()
                process_totals(reset=True)
                d = run_diagnose(None, str(data), str(WORK / f"diag_{variant}_{name}_{k}{'' if executor == 'process' else '_' + executor}"), str(config),
                                 printer=lambda line: None, history=False)
                seconds.append(time.perf_counter() - t1)
                sims.append(process_totals())
                named.append(d.effect)
                verdicts.append({"variant": variant, "data_set": name, "seed": k, "effect": d.effect,
                                 "effects": d.effects, "chi2_per_dof_before": d.before["chi2_per_dof"],
                                 "ambiguous": d.rounds[0].get("ambiguous", []) if d.rounds else [],
                                 "reason": d.rounds[0]["reason"] if d.rounds else "", "notes": d.notes,
                                 "simulations": sims[-1]})
                print(f"[fmu diagnosis] {variant} {name} seed {k}: {d.effect} ({seconds[-1]:.0f} s; "
                      f"{sims[-1]['simulations']} simulations, {sims[-1]['simulated_s']:.4g} s simulated, "
                      f"{sims[-1]['busy_worker_s']:.3g} s busy; runs reused: {sims[-1]['reused_base_runs']} base, "
                      f"{sims[-1]['reused_perturbed_runs']} perturbed)", flush=True)
            want = "none" if name == "control" else name
            right = sum(1 for v in verdicts if v["variant"] == variant and v["data_set"] == name and
                        (v["effect"] == want or (v["effect"] == "ambiguous" and want in v["ambiguous"])))
            rows.append({"variant": variant, "data_set": name, "right": right, "total": n_seeds,
                         "verdicts": dict(Counter(named)), "seconds_per_diagnosis": float(np.mean(seconds)),
                         "truth_seconds": truth_seconds,
                         "simulations_per_diagnosis": float(np.mean([t["simulations"] for t in sims])),
                         "busy_worker_s_per_diagnosis": float(np.mean([t["busy_worker_s"] for t in sims])),
                         "chi2_per_dof_before_median": float(np.median(
                             [v["chi2_per_dof_before"] for v in verdicts[-n_seeds:]]))})
    out = {"n_seeds": n_seeds, "rows": rows, "verdicts": verdicts, "wall_seconds": time.perf_counter() - t_start,
           "truth_steady": TRUTH_STEADY, "model_steady": MODEL_STEADY, "switches": SWITCHES}
    out["executor"] = executor
    suffix = "" if executor == "process" else "_" + executor
    out_json, out_md = (p.with_name(p.stem + suffix + p.suffix) for p in (OUT_JSON, OUT_MD))
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(out, indent=1))
    lines = [f"# calib diagnose on the bundled FMUs ({n_seeds} seeds, {out['wall_seconds'] / 60:.1f} min)", "",
             "Truth: the FMU at 72 steps/rev, 10 + 4 revolutions; model: the same FMU at 24 steps/rev, 4 + 2.", "",
             "| variant | data set | right / total | verdicts | χ²/dof before (median) | simulations / diagnosis "
             "| s / diagnosis |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['variant']} | {r['data_set']} | {r['right']} / {r['total']} | "
                     f"{', '.join(f'{k} {v}' for k, v in r['verdicts'].items())} | "
                     f"{r['chi2_per_dof_before_median']:.3g} | {r['simulations_per_diagnosis']:.0f} | "
                     f"{r['seconds_per_diagnosis']:.0f} |")
    out_md.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    if executor != "process":
        return out
    from publish import command_line, publish

    publish("diagnosis_fmu", {k: v for k, v in out.items() if k != "verdicts"}, command_line(),
            f"{n_seeds} noise seed(s) per data set, {out['wall_seconds'] / 60:.1f} min in all.\n\n"
            + "\n".join(lines[2:]) + "\n")
    return out


def noisy_table(variant: str, data_set: str, clean: np.ndarray, seed: int) -> Path:
    """The data set's measurement table for noise seed ``seed``: the truth's outputs ``clean`` plus 1 % of each
    channel's RMS as Gaussian noise, with that σ; written under :data:`WORK`, its path returned."""
    from calib.measurements import Measurements
    rng = np.random.default_rng(SEED0 + 10 * seed)
    sigma = 0.01 * np.sqrt(np.mean(clean ** 2, axis=0))
    noisy = clean + rng.standard_normal(clean.shape) * sigma
    meas = Measurements(conditions(), tuple(CHANNELS), noisy, np.broadcast_to(sigma, noisy.shape).copy(),
                        source=f"fmu {variant} {data_set} seed {seed}")
    data = WORK / f"{variant}_{data_set}_{seed}.csv"
    meas.write_csv(data)
    return data


def case(variant: str = "A", data_set: str = "pitch_offset_blade1", seed: int = 0, executor: str = "process",
         jacobian: dict | None = None) -> dict:
    """One diagnosis of :func:`run` (``variant``, ``data_set``, noise seed ``seed``) with its FMU
    simulations counted per step: :func:`calib.fmu.tally.process_totals` read at every progress line
    (the step that line starts or reports), so the counts say where the simulations went.

    ``executor``: ``process`` (as :func:`run`) or ``dask`` (a Dask LocalCluster of 2 workers); ``jacobian``
    as :func:`config_text` (e.g. ``{"differences": "forward", "relative_step": 0.1}``). Writes
    nothing to the validation pages (counts only; the wall clock of a loaded machine is not published).
    """
    from calib.diagnosis.command import run_diagnose
    from calib.fmu.tally import process_totals
    WORK.mkdir(parents=True, exist_ok=True)
    tag = "" if not jacobian else "_" + "_".join(f"{v}" for v in jacobian.values())
    config = WORK / f"config_{variant}_{executor}{tag}.toml"
    config.write_text(config_text(variant, executor, jacobian))
    clean = truth_values(variant, DATA_SETS[data_set], WORK)
    data = noisy_table(variant, data_set, clean, seed)
    steps = []

    def printer(line):
        steps.append({"line": line, "cpu_s": time.process_time(), **process_totals()})
        print(f"  [{steps[-1]['simulations']:5d} sims, {steps[-1]['reused_base_runs']:4d} + "
              f"{steps[-1]['reused_perturbed_runs']:4d} reused] {line}", flush=True)

    process_totals(reset=True)
    cpu0, t0 = time.process_time(), time.perf_counter()
    d = run_diagnose(None, str(data), str(WORK / f"case_{variant}_{data_set}_{seed}_{executor}{tag}"), str(config),
                     printer=printer, history=False)
    out = {"variant": variant, "data_set": data_set, "seed": seed, "executor": executor, "jacobian": jacobian,
           "effect": d.effect,
           "effects": d.effects, "chi2_per_dof_before": d.before["chi2_per_dof"],
           "chi2_per_dof_with_effects": d.with_effects["chi2_per_dof"], "totals": process_totals(),
           "main_process_cpu_s": time.process_time() - cpu0, "wall_s": time.perf_counter() - t0, "steps": steps}
    print(json.dumps({k: v for k, v in out.items() if k != "steps"}, indent=1))
    return out


#: The difference schemes :func:`difference_error` compares (scheme, relative step) and its reference: the
#: mappings' default until issue 38's item 1 (central 0.01), the step above the output jumps (bench_fmu_run's
#: study, one-sided: the default since), and central at that step.
SCHEMES = (("central", 0.01), ("forward", 0.1), ("central", 0.1))
REFERENCE = ("central", 0.2)


def difference_error(variant: str = "A") -> dict:
    """The Jacobian of the diagnosis's FMU model (:func:`config_text`: the correction field's 8 nodes and
    the 3 candidates, at nominal, at the campaign) by each of :data:`SCHEMES`, against :data:`REFERENCE`.

    Per scheme and parameter: the column's relative error in the noise-whitened norm
    ``||ΔG_j / σ|| / ||G_j / σ||`` and the largest entry ``|ΔG_kcj| σ_j / σ_kc`` with ``σ_j = 1 / ||G_j / σ||``
    (the σ of that parameter fitted alone): the error of a linearized prediction over that σ, in noise σ;
    σ the campaign's 1 % of each channel's RMS. Also the simulations each scheme made.
    """
    from calib.corrections import CorrectionGrid
    from calib.executors import ProcessExecutor
    from calib.fmu.base_runs import BaseRunCache
    from calib.fmu.tally import process_totals
    from calib.models.from_config import model_from_workflow

    WORK.mkdir(parents=True, exist_ok=True)
    cond, grid = conditions(), CorrectionGrid([0.0, 10.0], [0.6, 1.0])
    cache = BaseRunCache()
    with ProcessExecutor(2) as ex:
        def jacobian(differences, step):
            model = model_from_workflow({"kind": "fmu", "variant": variant, "switches": SWITCHES, "steady": MODEL_STEADY,
                                         "parameters": CANDIDATES, "corrections": True,
                                         "jacobian": {"differences": differences, "relative_step": step}},
                                        {"name": "nrel5mw"}, CHANNELS, str(WORK / "difference.toml"), WORK, grid=grid,
                                        executor=ex)
            model.base_runs = cache
            try:
                before = process_totals()["simulations"]
                ev, G = model.jacobian(np.array([q.nominal for q in model.parameters]), cond)
                return ev, G, [q.name for q in model.parameters], process_totals()["simulations"] - before
            finally:
                model.close()
        ev, G_ref, names, n_ref = jacobian(*REFERENCE)
        found = {k: jacobian(*k) for k in SCHEMES}
    sigma = 0.01 * np.sqrt(np.nanmean(ev.values ** 2, axis=0))[None, :, None]
    W = G_ref / sigma
    norm = np.sqrt(np.nansum(W ** 2, axis=(0, 1)))
    out = {"parameters": names, "reference": f"{REFERENCE[0]} {REFERENCE[1]:g}", "reference_simulations": n_ref}
    for (scheme, step), (_, G, _, n) in found.items():
        dW = (G - G_ref) / sigma
        out[f"{scheme} {step:g}"] = {
            "simulations": n,
            "column_error": (np.sqrt(np.nansum(dW ** 2, axis=(0, 1))) / norm).tolist(),
            "max_entry_error": (np.nanmax(np.abs(dW), axis=(0, 1)) / norm).tolist()}
    return out


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "difference-error":
        # python benchmarks/bench_fmu_diagnosis.py difference-error [VARIANT [OUT.json]]
        res = difference_error(*(sys.argv[2:3]))
        print(json.dumps(res, indent=1))
        if len(sys.argv) > 3:
            Path(sys.argv[3]).write_text(json.dumps(res, indent=1))
    elif len(sys.argv) > 1 and sys.argv[1] == "case":
        # python benchmarks/bench_fmu_diagnosis.py case [VARIANT DATA_SET SEED EXECUTOR [OUT.json
        # [DIFFERENCES RELATIVE_STEP]]]
        args = sys.argv[2:]
        jac = {"differences": args[5], "relative_step": float(args[6])} if len(args) > 6 else None
        res = case(*(args[:2]), *(int(a) for a in args[2:3]), *(args[3:4]), jacobian=jac)
        if len(args) > 4:
            Path(args[4]).write_text(json.dumps(res, indent=1))
    else:
        # python benchmarks/bench_fmu_diagnosis.py [N_SEEDS [EXECUTOR]]
        run(int(sys.argv[1]) if len(sys.argv) > 1 else 1, executor=sys.argv[2] if len(sys.argv) > 2 else "process")
