"""Errors in variables through an FMU: what the default joint estimator costs in simulations, and its
coverage on a twin of the bundled FMI 3.0 FMU (issue 40).

The joint estimator solves every point's true conditions at each parameter vector, and an FMU gives no
derivatives with respect to its inputs: each inner step differences the outputs in every uncertain
condition (two simulations per point and condition). This study counts the simulations and the wall
clock of the three ways to meet uncertain conditions on the same data, serially (one worker):

- ``output_error``: ``errors_in_variables = "ignore"`` (the conditions taken as exact; the noise as stated);
- ``marginal``: the effective covariance, J_u at the estimate, re-fitted until it settles;
- ``joint``: the default.

The twin is the conformance matrix's ``fmu_b`` (``tests/conformance.py``: the bundled FMI 3.0 FMU, a 3 × 2
correction field and two blade pitch offsets, quasi-steady, 8 operating points, 1 % output noise), its
truth the matrix's, and the measured conditions scattered as in the matrix's ``uncertain`` cells: wind
speed 3 % and pitch 0.2 deg per point, the σ stated. Each replicate draws the output noise and the
conditions' scatter again (seeds ``FIRST_SEED`` …, never used by the test suite nor for tuning).

Coverage, judged as in the conformance matrix: the share of replicates whose NEES of the whole scaled
vector lies below the 95 % quantile of χ²(n), and the share of the non-field parameters' 95 % intervals
holding the truth. Few replicates (each costs about a minute of simulation): the binomial 95 % range of
the shares is printed beside them.

``python benchmarks/bench_eiv_fmu.py [N]`` (N replicates, default 8); publishes
``docs/validation/data/errors_in_variables_fmu.json`` (the errors-in-variables page).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, HERE)

#: A statistical study with FMU simulations: `make validate`.
SUITE = "validate"

MODEL = "fmu_b"
FIRST_SEED = 5100
ESTIMATORS = {"output_error": "ignore", "marginal": "marginal", "joint": "joint"}
LEVEL = 0.95


def replicate(seed: int, workdir: Path) -> dict:
    """One data set of the twin (seed ``seed``) calibrated by each estimator: figures per estimator."""
    from scipy import stats

    from calib.calibration import CalibrationSettings, Calibrator
    from calib.measurements import synthesize
    from conformance import NOISE, _exact_case, build_model, conditions_of, is_field, with_uncertain_conditions

    p_true, _ = _exact_case(MODEL, str(workdir))
    out = {}
    for name, mode in ESTIMATORS.items():
        model, prior_std = build_model(MODEL, "stated", None, workdir)
        try:
            channels = [c.name for c in model.channels]
            if name == "output_error":       # the data, drawn once per replicate with the first model
                clean = synthesize(model, p_true, conditions_of(MODEL), relative_sigma={c: NOISE for c in channels},
                                   seed=seed)
                meas = with_uncertain_conditions(clean, seed)
            before = model.simulation_summary()
            t0 = time.perf_counter()
            res = Calibrator(model, meas, CalibrationSettings(errors_in_variables=mode, noise="known",
                                                              prior_std=prior_std or None), name=name).run()
            wall = time.perf_counter() - t0
            after = model.simulation_summary()
        finally:
            model.close()
        names = [q["name"] for q in res.parameters]
        err = (res.estimate.p_hat - p_true) / res.estimate.scale
        cov = res.uncertainty.cov_p / np.outer(res.estimate.scale, res.estimate.scale)
        nees = float(err @ np.linalg.solve(cov, err))
        other = np.flatnonzero([not is_field(n) for n in names])
        z = np.abs(res.estimate.p_hat - p_true)[other] / res.uncertainty.std_p[other]
        out[name] = {"status": str(res.estimate.status), "message": res.estimate.message[:300],
                     "simulations": after["simulations"] - before["simulations"],
                     "simulated_s": after["simulated_s"] - before["simulated_s"], "wall_s": wall,
                     "nees": nees, "dof": int(err.size),
                     "inside": bool(nees <= stats.chi2.ppf(LEVEL, err.size)),
                     "held": [bool(v) for v in z <= stats.norm.ppf(0.5 + LEVEL / 2)],
                     "z": [float(v) for v in z], "names": [names[j] for j in other]}
    return out


def binomial_range(k: int, n: int) -> tuple[float, float]:
    """The Clopper–Pearson 95 % range of a share k/n."""
    from scipy import stats

    lo = 0.0 if k == 0 else float(stats.beta.ppf(0.025, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(0.975, k + 1, n - k))
    return lo, hi


def summarize(runs: list[dict], seeds: list[int]) -> dict:
    out = {"model": MODEL, "n_replicates": len(runs), "seeds": seeds, "level": LEVEL}
    for name in ESTIMATORS:
        recs = [r[name] for r in runs]
        inside = sum(r["inside"] for r in recs)
        held = [h for r in recs for h in r["held"]]
        out[name] = {"simulations_mean": float(np.mean([r["simulations"] for r in recs])),
                     "simulations_max": int(max(r["simulations"] for r in recs)),
                     "wall_s_mean": float(np.mean([r["wall_s"] for r in recs])),
                     "converged": sum(r["status"] == "converged" for r in recs),
                     "statuses": {s: sum(r["status"] == s for r in recs) for s in sorted({r["status"] for r in recs})},
                     "nees_inside": inside, "nees_inside_range": binomial_range(inside, len(recs)),
                     "intervals": len(held), "intervals_held": int(sum(held)),
                     "intervals_held_range": binomial_range(int(sum(held)), len(held)),
                     "nees_median": float(np.median([r["nees"] for r in recs])), "dof": recs[0]["dof"],
                     "not_converged": [{"seed": s, "status": r["status"], "message": r["message"]}
                                       for s, r in zip(seeds, recs) if r["status"] != "converged"]}
    base = out["output_error"]["simulations_mean"]
    for name in ESTIMATORS:
        out[name]["simulations_over_output_error"] = out[name]["simulations_mean"] / base if base else None
    return out


def markdown(f: dict) -> str:
    rows = [f"### Through the bundled FMU (FMI 3.0): cost and coverage, {f['n_replicates']} replicates", "",
            "| estimator | simulations per calibration (mean / max) | × output error | wall s (serial) | converged | "
            f"NEES ≤ χ²₉₅({f['joint']['dof']}) | non-field 95 % intervals holding the truth |",
            "|---|---|---|---|---|---|---|"]
    for name in ESTIMATORS:
        r = f[name]
        lo, hi = r["nees_inside_range"]
        lo2, hi2 = r["intervals_held_range"]
        rows.append(f"| {name} | {r['simulations_mean']:.0f} / {r['simulations_max']} | "
                    f"{r['simulations_over_output_error']:.2g} | {r['wall_s_mean']:.1f} | "
                    f"{r['converged']}/{f['n_replicates']} | {r['nees_inside']}/{f['n_replicates']} "
                    f"({lo:.0%}–{hi:.0%}) | {r['intervals_held']}/{r['intervals']} ({lo2:.0%}–{hi2:.0%}) |")
    rows += ["", f"Twin `{f['model']}` of the conformance matrix (`tests/conformance.py`), stated priors, output noise "
             "known, seeds " + f"{f['seeds'][0]}…{f['seeds'][-1]}; measured conditions scattered 3 % (wind speed) and "
             "0.2 deg (pitch) per point. In parentheses the Clopper–Pearson 95 % range of each share (few replicates). "
             "Simulations counted by the FMU model's tally, serial, one worker.", ""]
    return "\n".join(rows)


def run(n_replicates: int = 8, progress=print) -> dict:
    """The study over ``n_replicates`` replicates; publishes the figures."""
    from publish import command_line, publish

    seeds = list(range(FIRST_SEED, FIRST_SEED + n_replicates))
    runs = []
    with tempfile.TemporaryDirectory(prefix="bench_eiv_fmu-") as tmp, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*InitialUnknowns")
        for k, seed in enumerate(seeds, start=1):
            runs.append(replicate(seed, Path(tmp)))
            progress(f"[eiv fmu {k}/{n_replicates}] seed {seed}: " + ", ".join(
                f"{n} {r['status']} {r['simulations']} sims NEES {r['nees']:.1f}" for n, r in runs[-1].items()))
    figures = summarize(runs, seeds)
    figures["published"] = publish("errors_in_variables_fmu", figures, command_line(), markdown(figures))
    return figures


if __name__ == "__main__":
    result = run(int(sys.argv[1]) if len(sys.argv) > 1 else 8)
    print(markdown(result))
