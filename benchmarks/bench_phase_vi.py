"""How the Phase VI conclusions depend on the noise model (real data, ``workflows/phase_vi.toml``).

For each noise model: what the diagnosis names from all channels (with its
likelihood-ratio statistic Λ), and the leave-one-wind-speed-out validation of the hub-load
calibration with the named effect (torque: mean |error| calibrated vs nominal at the
held-out wind speeds, held-out measurements inside the 95 % prediction intervals). Noise
models:

- ``relative_ml`` (the workflow's): stated fractions of each channel's RMS (hub loads 3 %,
  c_n 5 %, c_t 10 %) times one ML factor;
- the same with the pressure taps weighted half and twice as much relative to the hub loads;
- ``relative`` without the ML factor (the stated fractions taken as the truth);
- ``ml``: one ML σ per channel (started from the stated fractions).

First it runs the shipped workflow itself (``calib run workflows/phase_vi.toml``) and records
what the validation page states of it: the named effect and its statistics, per stage the
noise σ the ML factor gives, the directions the data inform, the stall-delay strength and the
leave-one-wind-speed-out figures of torque and thrust. Everything is published for the page
(``docs/validation/data/phase_vi.json``).

``python benchmarks/bench_phase_vi.py`` (about 1-2 min per noise model here, plus the workflow).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from calib.diagnosis.core import diagnose  # noqa: E402
from calib.diagnosis.in_workflow import named_effect_specs  # noqa: E402
from calib.measurements import read_measurements  # noqa: E402
from calib.words import p_text  # noqa: E402
from calib.workflow import load_workflow, prepare, run_workflow  # noqa: E402
from calib.workflow.validation import ValidationSettings, leave_one_out  # noqa: E402

#: A statistical or soak study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

WORKFLOW = os.path.join(ROOT, "workflows", "phase_vi.toml")
STATED = {"torque": 0.03, "thrust": 0.03, "cn": 0.05, "ct": 0.10}
MODELS = {
    "relative_ml (stated weights)": ("relative_ml", STATED),
    "relative_ml, taps weighted x0.5": ("relative_ml", {**STATED, "cn": 0.10, "ct": 0.20}),
    "relative_ml, taps weighted x2": ("relative_ml", {**STATED, "cn": 0.025, "ct": 0.05}),
    "relative (stated, no ML factor)": ("relative", STATED),
    "ml per channel": ("ml", STATED),
}


def workflow_figures(out_dir: str) -> dict:
    """Run the shipped workflow into ``out_dir``; the figures its validation page states."""
    import json

    import numpy as np

    from calib.calibration.result_files import load_result
    from calib.workflow.validation import INFORMED_LEVEL

    t0 = time.perf_counter()
    outcomes = run_workflow(WORKFLOW, out_dir, progress=False)
    seconds = time.perf_counter() - t0
    with open(os.path.join(out_dir, "diagnosis", "diagnosis.json")) as fh:
        diag = json.load(fh)
    first = diag["rounds"][0]["candidates"]
    best = first[0]
    runner = first[1] if len(first) > 1 else None
    figures = {"workflow_seconds": seconds, "named": diag["effect"], "effects": diag["effects"],
               "best": {k: best[k] for k in ("name", "lr_statistic", "p_value", "weight", "bic", "n_params")},
               "runner_up": None if runner is None else {"name": runner["name"],
                                                         "delta_bic": runner["bic"] - best["bic"]},
               "chi2_per_dof": {k: diag[k]["chi2_per_dof"] for k in ("before", "with_effects", "after")},
               "stages": {}}
    for o in outcomes:
        stage = os.path.basename(o.out_dir)
        res = load_result(o.out_dir)
        names = [q["name"] for q in res.parameters]
        i = names.index("stall_delay_strength")
        rms = np.sqrt(np.mean(res.fit.measured ** 2, axis=0))
        sig = np.broadcast_to(res.fit.noise_sigma, res.fit.measured.shape)[0]
        with open(os.path.join(o.out_dir, "validation.json")) as fh:
            val = json.load(fh)
        figures["stages"][stage] = {
            "estimator": res.estimator, "retained": int(np.sum(res.identifiability.retained)),
            "informed": int(np.sum(res.identifiability.singular_values >= INFORMED_LEVEL)),
            "noise_percent_of_rms": {ch: float(100 * sig[k] / rms[k]) for k, ch in enumerate(res.channels)
                                     if ch in ("torque", "thrust")},
            "stall_delay_strength": {"value": float(res.estimate.p_hat[i]), "std": float(res.uncertainty.std_p[i]),
                                     "verdict": res.identifiability.verdicts[i]["verdict"]},
            "leave_one_out": {s_["channel"]: s_ for s_ in val["summary"]}}
    return figures


def markdown(wf: dict, noise: dict) -> str:
    """The page's tables: the workflow's findings and the noise-model sensitivity."""
    b, r = wf["best"], wf["runner_up"]
    c = wf["chi2_per_dof"]
    runner = "" if r is None else f"; runner-up {r['name']} at ΔBIC {r['delta_bic']:.1f}"
    lines = [f"**Named:** `{wf['named']}` (first candidate {b['name']}: Λ = {b['lr_statistic']:.3g} for "
             f"{b['n_params']} parameter(s), p = {p_text(b['p_value'])}, BIC weight {b['weight']:.2f}{runner}); "
             f"χ²/dof {c['before']:.3g} nominal → {c['with_effects']:.3g} with the effect → {c['after']:.3g} "
             "recalibrated.", "",
             "| stage | estimator | noise σ, % of RMS torque / thrust | directions kept / informed (s ≥ 0.5) | "
             "stall-delay strength | held-out torque: mean \\|error\\| calibrated / nominal [N m], inside 95 % | "
             "held-out thrust [N], inside |", "|---|---|---|---|---|---|---|"]
    for stage, st in wf["stages"].items():
        n = st["noise_percent_of_rms"]
        sd = st["stall_delay_strength"]
        cells = [stage.replace("_", " "), st["estimator"], f"{n.get('torque', float('nan')):.1f} / "
                 f"{n.get('thrust', float('nan')):.1f}", f"{st['retained']} / {st['informed']}",
                 f"{sd['value']:.3g} ± {sd['std']:.2g} ({sd['verdict']})"]
        for ch in ("torque", "thrust"):
            v = st["leave_one_out"][ch]
            cells.append(f"{v['mean_abs_error_calibrated']:.0f} / {v['mean_abs_error_nominal']:.0f}, "
                         f"{v['inside']} of {v['folds']}")
        lines.append("| " + " | ".join(cells) + " |")
    lines += ["", "Sensitivity to the noise model (the diagnosis on all channels, then the hub-load "
                  "calibration with the named effect, one wind speed left out at a time):", "",
              "| noise model | named | Λ (first round) | held-out torque: mean \\|error\\| calibrated / nominal "
              "[N m] | inside 95 % |", "|---|---|---|---|---|"]
    for label, v in noise.items():
        named = ", ".join(v["effects"]) or v["named"]
        lines.append(f"| {label} | {named} | {v['lambda_first']:.3g} | {v['torque_mae_calibrated']:.0f} / "
                     f"{v['torque_mae_nominal']:.0f} | {v['inside']} of {v['folds']} |")
    return "\n".join(lines) + "\n"


def run() -> dict:
    """The workflow, then the noise models; published for the validation page."""
    import tempfile

    from publish import command_line, publish

    with tempfile.TemporaryDirectory() as tmp:
        wf = workflow_figures(os.path.join(tmp, "phase_vi"))
    noise = noise_models()
    publish("phase_vi", {"workflow": wf, "noise_models": noise}, command_line(), markdown(wf, noise))
    return {"workflow": wf, "noise_models": noise}


def noise_models() -> dict:
    workflow = load_workflow(WORKFLOW)
    setup = prepare(workflow)
    file = os.path.join(workflow.base_dir, workflow.measurements.file)
    meas = read_measurements(file, setup.channels)
    grid = setup.grid(meas.conditions)
    dset, _ = setup.diagnosis
    hub = ["torque", "thrust"]
    out = {}
    for label, (noise, rel) in MODELS.items():
        t0 = time.perf_counter()
        st = dataclasses.replace(setup.calibration, noise=noise, relative_sigma=rel).validate()
        diag = diagnose(setup.rotor, meas, grid, setup.settings, st, dset, rotor_source=setup.rotor_spec)
        effects = named_effect_specs(diag, skip=setup.nuisance)
        lam = diag.rounds[0]["candidates"][0].lr_statistic if diag.rounds else float("nan")
        val = leave_one_out(lambda: setup.model(grid, hub, None, effects), meas.select_channels(hub), st,
                            ValidationSettings("wind_speed", ("torque",)))
        s = val.summary("torque")
        out[label] = {"named": diag.effect, "effects": diag.effects, "lambda_first": lam,
                      "torque_mae_nominal": s["mean_abs_error_nominal"],
                      "torque_mae_calibrated": s["mean_abs_error_calibrated"], "inside": s["inside"],
                      "folds": s["folds"], "seconds": time.perf_counter() - t0}
        print(f"[phase_vi] {label}: named {diag.effect} {diag.effects} (Λ first round {lam:.3g}); torque held out: "
              f"{s['mean_abs_error_calibrated']:.0f} vs nominal {s['mean_abs_error_nominal']:.0f} N m, "
              f"{s['inside']}/{s['folds']} inside ({out[label]['seconds']:.0f} s)", flush=True)
    return out


if __name__ == "__main__":
    run()
