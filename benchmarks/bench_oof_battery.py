"""Out-of-family battery of the diagnosis (issue 25, item 1): truth from WISDEM's CCBlade.

Data from an independent BEM code (CCBlade, in ``.bench-venv``) on calib's embedded NREL 5-MW
with its own polars, 63 operating points, power, thrust, torque and the flap moment about the
rotor centre, 1 % noise; one hidden effect per data set written in CCBlade's world with a form
that differs from calib's own effect models (``oof_battery/hidden_effects.py``), and controls
without any effect; two set-ups (rigid axisymmetric; tilted and coned with shear and 4 sectors);
``n_seeds`` noise seeds each. calib's diagnosis runs on every data set with a config that states
the set-up the data were made with; the figures say per set-up and data set how often it named
the right effect (``oof_battery/runner.py`` defines "right"), what it named instead, and how well
calib's native BEM agrees with CCBlade without effect and noise (per channel, RMS and max of the
relative difference: the default of a model-form tolerance).

``python benchmarks/bench_oof_battery.py [n_seeds]`` (default 20); under ``make validate``
``run(n_seeds=20)``. Writes ``bench_output/oof_battery.json`` and ``bench_output/oof_battery.md``;
data, configs, diagnoses and ``verdicts.jsonl`` (a killed battery resumes from it) under
``bench_output/oof_battery/``. Two worker processes at most. Measured 2026-11-25 on the shared
2-core machine: 20 seeds, 240 diagnoses in 17.6 min wall (35 min of diagnosis time; generating
the data 19 s); 0.6-3 s per control, up to 40 s per tilted blockage data set. Each run states
its own figure in ``battery_wall_seconds``.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from oof_battery import campaign, generate, runner  # noqa: E402

#: A statistical or soak study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

ROOT = HERE.parent
OUT_JSON = ROOT / "bench_output" / "oof_battery.json"
OUT_MD = ROOT / "bench_output" / "oof_battery.md"


def agreement_markdown(agreement: dict) -> str:
    rows = ["| set-up | polars in calib | " + " | ".join(campaign.CHANNELS) + " |",
            "|---|---|" + "---|" * len(campaign.CHANNELS)]
    for setup, a in agreement.items():
        for kind, label in (("default", "as given (calib's default)"), ("ccairfoil_smoothing",
                                                                        "CCAirfoil's spline (diagnostic)")):
            if a.get(kind):
                cells = [f"{a[kind][c]['rms_pct']:.3g} / {a[kind][c]['max_pct']:.3g}" for c in campaign.CHANNELS]
                rows.append(f"| {setup} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def run(n_seeds: int = 20, workers: int = runner.MAX_WORKERS, tolerance: str | None = None) -> dict:
    """Generate the battery, diagnose every data set, write the figures; returns them (``run_all``).

    Parameters
    ----------
    n_seeds : int
        Noise seeds per (set-up, data set).
    workers : int
        Diagnoses in parallel (at most 2).
    tolerance : {None, "measured"}
        None: calib's default ``[diagnosis]``; ``"measured"``: ``model_form_tolerance`` set to the
        agreement measured here (``generate.tolerance_from``); figures then go to
        ``bench_output/oof_battery_tolerance.json`` / ``.md`` and data to ``bench_output/oof_battery_tolerance/``.
    """
    t0 = time.perf_counter()
    suffix = "" if tolerance is None else "_tolerance"
    out_dir = generate.OUT_DIR.with_name(generate.OUT_DIR.name + suffix)
    out_json, out_md = (OUT_JSON.with_name(f"oof_battery{suffix}.json"), OUT_MD.with_name(f"oof_battery{suffix}.md"))
    try:
        gen = generate.generate(n_seeds, out_dir, tolerance=tolerance)
    except Exception as exc:  # noqa: BLE001  (never crash the benchmark runner)
        return {"error": f"generating the battery failed: {type(exc).__name__}: {exc}"}
    t1 = time.perf_counter()
    records = runner.run_battery(gen["files"], gen["configs"], out_dir, workers=workers)
    battery_seconds = time.perf_counter() - t1
    table = runner.tabulate(records)
    figures = {
        "n_seeds": n_seeds, "seeds": f"{campaign.SEED0}..{campaign.SEED0 + n_seeds - 1}",
        "n_diagnoses": len(records), "workers": workers,
        "generate_seconds": t1 - t0, "battery_wall_seconds": battery_seconds,
        "diagnosis_cpu_seconds": sum(r["seconds"] for r in records),
        "total_wall_seconds": time.perf_counter() - t0,
        "agreement_pct": gen["agreement"], "model_form_tolerance_default": generate.tolerance_from(gen["agreement"]),
        "model_form_tolerance_in_force": gen["tolerance"],
        "table": table, "effect_size_chi2_per_residual": gen["effect_size"],
        "truth_details": gen["truth_details"], "hidden_effect_parameters": gen["parameters"],
        "data_sets": campaign.DATA_SETS, "setups": campaign.SETUPS, "versions": gen["versions"],
        "records": records,
    }
    for key, row in table.items():
        figures[f"{key} right"] = f"{row['right']}/{row['n']}"
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(figures, indent=1, default=str))
    in_force = ("calib's default [diagnosis]" if gen["tolerance"] is None else "[diagnosis] model_form_tolerance "
                + ", ".join(f"{c} {100 * v:.3g} %" for c, v in gen["tolerance"].items()))
    md = (f"# Out-of-family battery ({n_seeds} seeds, {len(records)} diagnoses, "
          f"{battery_seconds / 60:.1f} min on {workers} processes; {in_force})\n\n"
          "Right = the first verdict names the data set's effect (or `ambiguous` with it); controls: `none`. "
          "alone = right with no second effect named.\n\n" + runner.markdown(table) +
          "\n## calib's native BEM vs CCBlade (no effect, no noise): RMS / max of 100 (calib − CCBlade)/CCBlade "
          "[%]\n\n" + agreement_markdown(gen["agreement"]))
    out_md.write_text(md)
    print(md, flush=True)
    if tolerance is None:
        publish_figures(figures, md.split("\n", 2)[2])
    return figures


def publish_figures(figures: dict, tables: str) -> str:
    """The battery's tables for the validation page (``docs/validation/data/diagnosis_out_of_family.json``)."""
    from publish import command_line, publish

    keep = ("n_seeds", "seeds", "n_diagnoses", "workers", "diagnosis_cpu_seconds", "agreement_pct",
            "model_form_tolerance_default", "table", "versions")
    head = (f"{figures['n_diagnoses']} diagnoses ({figures['n_seeds']} noise seeds per data set, seeds "
            f"{figures['seeds']}), {figures['diagnosis_cpu_seconds'] / 60:.1f} min of diagnosis time in all "
            f"({figures['workers']} processes; a killed battery resumes from its recorded verdicts).\n\n")
    return publish("diagnosis_out_of_family", {k: figures[k] for k in keep}, command_line(), head + tables)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("n_seeds", nargs="?", type=int, default=20, help="noise seeds per data set (default 20)")
    ap.add_argument("--workers", type=int, default=runner.MAX_WORKERS, help="parallel diagnoses (at most 2)")
    ap.add_argument("--tolerance", choices=("measured",), default=None,
                    help="run with [diagnosis] model_form_tolerance = the BEM-vs-CCBlade agreement measured here")
    args = ap.parse_args()
    res = run(args.n_seeds, args.workers, args.tolerance)
    sys.exit(1 if "error" in res else 0)
