"""How the Phase VI conclusions depend on the noise model (real data, ``workflows/phase_vi.toml``).

For each noise model: what the discrepancy workflow names from all channels (with its
likelihood-ratio statistic Λ), and the leave-one-wind-speed-out validation of the hub-load
calibration with the named effect (torque: mean |error| calibrated vs nominal at the
held-out wind speeds, held-out measurements inside the 95 % prediction intervals). Noise
models:

- ``relative_ml`` (the workflow's): stated fractions of each channel's RMS (hub loads 3 %,
  c_n 5 %, c_t 10 %) times one ML factor;
- the same with the pressure taps weighted half and twice as much relative to the hub loads;
- ``relative`` without the ML factor (the stated fractions taken as the truth);
- ``ml``: one ML σ per channel (started from the stated fractions).

``python benchmarks/bench_phase_vi.py`` (about 1-2 min per noise model here).
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from calib.campaign import ValidationSettings, leave_one_out, named_effect_specs  # noqa: E402
from calib.discrepancy import diagnose  # noqa: E402
from calib.measurements import read_measurements  # noqa: E402
from calib.workflow import load_workflow, prepare  # noqa: E402

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


def run() -> dict:
    cfg = load_workflow(WORKFLOW)
    setup = prepare(cfg)
    file = os.path.join(cfg["_dir"], cfg["measurements"]["file"])
    meas = read_measurements(file, setup.channels)
    grid = setup.grid(meas.conditions)
    dset, _ = setup.diagnosis
    hub = ["torque", "thrust"]
    out = {}
    for label, (noise, rel) in MODELS.items():
        t0 = time.perf_counter()
        st = dataclasses.replace(setup.calibration_settings, noise=noise, relative_sigma=rel).validate()
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
