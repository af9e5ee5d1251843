"""Predictions by extrapolation: calibrate on one band of wind speed, predict the other (issue 26).

Three families of data, each split both ways at the median wind speed (``[validation] split =
"band"``, :mod:`calib.workflow.validation`), each calibrated with both estimators:

- **out of family**: the committed CCBlade data sets of ``tests/data/oof`` (WISDEM CCBlade on
  the NREL 5-MW with its own polars; a control and three hidden effects written in CCBlade's
  world: rotational augmentation, Reynolds following, leading-edge erosion; rigid and tilted
  set-ups; 63 points, power, thrust, torque, hub flap moment, 1 % noise stated per point).
  The calibrated model: the native BEM with the set-up the data state, a correction field on
  automatic α nodes × 4 η nodes and a pitch offset;
- **measured**: the NREL Phase VI sequence of ``workflows/phase_vi.toml`` (its two stages);
- **prior draws**: the wind-tunnel twin (d) of ``bench_coverage.py`` (a truth drawn from the
  smooth-field prior on a 1° × 0.025 grid), split at λ 5 (calibrate at low λ and predict high,
  and the reverse), ``n_seeds`` draws.

Per split: held-back χ²/N against the measurements with the noise alone, calibrated and nominal
(is the calibrated model better than the nominal one where it was not fitted?), the fraction of
held-back measurements inside the 95 % interval (noise² + prediction variance), χ²/N with the
prediction variance, and points that failed to evaluate. And the decision of
:func:`calib.calibration.prediction.field_amplitude` measured: the same figures with the correction field
between and beyond the nodes carried at the stated prior's amplitude, at the prior check's τ̂, and at its
95 % upper bound (calib's rule), from each held-back row's field part of the variance.

Run: ``python benchmarks/bench_prediction.py [n_seeds]`` (default 12; part of ``make validate``).
Writes ``bench_output/prediction.json``, and the figures the documentation's validation page
renders, with the date and the commit, to ``docs/validation/data/prediction.json``.
"""

from __future__ import annotations

import dataclasses
import json
import re
import sys
import time
from pathlib import Path

import numpy as np

#: A statistical study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

ROOT = Path(__file__).resolve().parent.parent
OOF = ROOT / "tests" / "data" / "oof"
OUT = ROOT / "bench_output" / "prediction"
ESTIMATORS = ("map", "truncated")


#: How the correction field between and beyond the nodes enters a band, the alternatives measured side by side
#: (calib.calibration.prediction.field_amplitude): its amplitude in units of the stated prior.
FIELD_RULES = {"stated": "the stated prior, 1", "estimate": "the prior check's τ̂",
               "bound": "the prior check's 95 % upper bound (calib's rule)"}
Z95 = 1.959964


def _rule_variance(r: dict, rule: str) -> float:
    """A held-back row's model variance with the field between and beyond the nodes at ``rule``'s amplitude
    (outside the calibration envelope; inside it every rule keeps the stated prior's)."""
    f, used = r.get("field_std", np.nan), r.get("field_amplitude", np.nan)
    if not (np.isfinite(f) and np.isfinite(used) and used > 0) or rule == "bound" or not r.get("outside"):
        return r["model_std"] ** 2
    a = 1.0 if rule == "stated" else r.get("prior_amplitude", np.nan)
    a = used if not np.isfinite(a) else a
    return r["model_std"] ** 2 + (a ** 2 / used ** 2 - 1.0) * f ** 2


def _split_figures(rows: list) -> dict:
    """Per fold direction: χ²/N (noise only) calibrated and nominal, inside the interval, failed; and per
    field rule (:data:`FIELD_RULES`) the points inside and χ²/N with the prediction variance (noise² + model
    variance)."""
    out = {}
    for fold in sorted({r["fold"] for r in rows}):
        rr = [r for r in rows if r["fold"] == fold]
        ok = [r for r in rr if r["status"] == "converged" and np.isfinite(r["predicted"])]
        cal = float(np.mean([((r["measured"] - r["predicted"]) / r["noise_std"]) ** 2 for r in ok])) if ok else np.nan
        nom = float(np.mean([((r["measured"] - r["nominal"]) / r["noise_std"]) ** 2 for r in ok])) if ok else np.nan
        rules = {}
        for rule in FIELD_RULES:
            z2 = [(r["measured"] - r["predicted"]) ** 2 / (r["noise_std"] ** 2 + _rule_variance(r, rule)) for r in ok]
            rules[rule] = {"inside": int(sum(z <= Z95 ** 2 for z in z2)), "chi2_sum": float(np.sum(z2))}
        out["low to high" if "at or below" not in fold else "high to low"] = {
            "chi2_per_n_calibrated": cal, "chi2_per_n_nominal": nom, "better_than_nominal": bool(cal <= nom),
            "inside": int(sum(bool(r["inside"]) for r in ok)), "rows": len(rr), "failed": len(rr) - len(ok),
            "chi2_per_n_predictive": rules["bound"]["chi2_sum"] / max(len(ok), 1), "rules": rules,
            # the 95 % half-width (noise² + model variance) at least the nominal model's error at the point
            "wider_than_nominal_misfit": int(sum(Z95 * np.hypot(r["noise_std"], r["model_std"])
                                                 >= abs(r["measured"] - r["nominal"]) for r in ok))}
    return out


def _workflow_text(name: str, data: Path, model_lines: str, estimator: str, channels: list) -> str:
    return f"""name = "{name}"
[rotor]
name = "nrel5mw"
[model]
{model_lines}
nuisance = ["pitch_offset"]
[grid]
alpha_nodes_deg = "auto"
eta_nodes = [0.25, 0.5, 0.75, 1.0]
[measurements]
file = "{data}"
[calibration]
noise = "known"
cd_min = 0.003
estimator = "{estimator}"
[validation]
leave_out = "wind_speed"
split = "band"
[[stages]]
name = "loads"
channels = {json.dumps(channels)}
"""


def out_of_family(estimator: str, say=print) -> dict:
    """The committed CCBlade data sets, both set-ups, band split on wind speed."""
    from calib.workflow import run_workflow

    out = {}
    for setup in ("rigid", "tilted"):
        cfg = (OOF / f"config_{setup}.toml").read_text()
        model = re.search(r"\[model\]\n(.*?)\n\n", cfg, re.S).group(1)
        for csv in sorted(OOF.glob(f"{setup}_*.csv")):
            name = csv.stem
            work = OUT / estimator / name
            work.mkdir(parents=True, exist_ok=True)
            wf = work / "workflow.toml"
            wf.write_text(_workflow_text(name, csv.resolve(), model, estimator,
                                         ["power", "thrust", "torque", "hub_flap_moment"]))
            t = time.perf_counter()
            run_workflow(wf, work / "out", progress=False, force=True, history=False)
            rows = json.loads((work / "out" / "stage1_loads" / "validation.json").read_text())["rows"]
            out[name] = _split_figures(rows)
            say(f"[prediction] {estimator} {name}: {out[name]} ({time.perf_counter() - t:.0f} s)")
    return out


def phase_vi(estimator: str, say=print) -> dict:
    """The Phase VI workflow's two stages with a band split on wind speed."""
    from calib.workflow import run_workflow

    text = (ROOT / "workflows" / "phase_vi.toml").read_text()
    text = re.sub(r'^estimator = ".*"$', f'estimator = "{estimator}"', text, flags=re.M)
    text = text.replace('leave_out = "wind_speed"', 'leave_out = "wind_speed"\nsplit = "band"')
    # relative paths of the workflow resolve against its folder: write the copy beside it
    wf = ROOT / "workflows" / f".bench_prediction_phase_vi_{estimator}.toml"
    wf.write_text(text)
    try:
        outcomes = run_workflow(wf, OUT / estimator / "phase_vi", progress=False, force=True, history=False)
    finally:
        wf.unlink()
    out = {}
    for k, o in enumerate(outcomes):
        folder = next((OUT / estimator / "phase_vi").glob(f"stage{k + 1}_*"))
        rows = json.loads((folder / "validation.json").read_text())["rows"]
        out[folder.name] = _split_figures(rows)
        say(f"[prediction] {estimator} Phase VI {folder.name}: {out[folder.name]}")
    return out


def prior_draws(estimator: str, n_seeds: int, say=print) -> dict:
    """Twin (d) of bench_coverage, split at λ 5, both ways."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_coverage import _fine_prior_draw, _setup

    from calib.calibration import CalibrationSettings, Calibrator
    from calib.measurements import synthesize
    from calib.workflow import truth_model

    workflow, rotor, settings, channels, cond, grid, model = _setup()
    rel = {c: float(workflow.noise.relative[c]) for c in channels}
    tmodel, _ = truth_model(rotor, channels, settings, workflow.truth, ("pitch_offset",))
    lam = cond.tip_speed_ratio(rotor.rotor_radius)
    idx = [[c.name for c in model.channels].index(c) for c in channels]
    out = {"low to high": [], "high to low": []}
    for seed in range(6000, 6000 + n_seeds):
        p_true = _fine_prior_draw(tmodel, model, grid, cond, seed, 0.003)
        meas = synthesize(tmodel, p_true, cond, relative_sigma=rel, channels=channels, seed=seed)
        for label, train in (("low to high", lam <= 5.0), ("high to low", lam > 5.0)):
            part = dataclasses.replace(meas, conditions=cond.subset(train), values=meas.values[train],
                                       sigma=None if meas.sigma is None else meas.sigma[train])
            res = Calibrator(model, part, CalibrationSettings(cd_min=0.003, estimator=estimator,
                                                              tightening=False)).run()
            test = cond.subset(~train)
            pred = res.predict(test, model)
            nominal = model.evaluate(res.estimate.p_nominal, test).values[:, idx]
            noise = res.fit.sigma[0]
            tau = float(res.uncertainty.prior_check.get("amplitude", np.nan))
            fold = "predicting above" if label == "low to high" else "predicting at or below"
            rows = [{"fold": fold, "status": "converged" if pred.status[k] == 0 else "failed",
                     "measured": float(meas.values[~train][k, j]), "predicted": float(pred.values[k, j]),
                     "nominal": float(nominal[k, j]), "noise_std": float(noise[j]), "model_std": float(pred.std[k, j]),
                     "field_std": float(pred.field_std[k, j]),
                     "field_amplitude": pred.field_amplitude if pred.outside[k] else 1.0,
                     "outside": pred.envelope[k] if pred.envelope else "",
                     "prior_amplitude": tau,
                     "inside": bool(abs(meas.values[~train][k, j] - pred.values[k, j])
                                    <= Z95 * np.hypot(noise[j], pred.std[k, j]))}
                    for k in range(pred.values.shape[0]) for j in range(len(channels))]
            out[label].append({"seed": seed, "status": res.estimate.status, **_split_figures(rows)[label]})
        say(f"[prediction] {estimator} twin (d) seed {seed}: "
            + ", ".join(f"{k} {v[-1]['chi2_per_n_calibrated']:.3g} vs nominal {v[-1]['chi2_per_n_nominal']:.3g}"
                        for k, v in out.items()))
    return out


def _splits(tree) -> list:
    """Every split record (a dict with ``inside``) in a family's nested results."""
    if isinstance(tree, list):
        return [s for x in tree for s in _splits(x)]
    if isinstance(tree, dict):
        return [tree] if "inside" in tree else [s for v in tree.values() for s in _splits(v)]
    return []


def summary(family) -> dict:
    """Over every split of a family: how often the calibrated held-back χ²/N is at most the nominal's,
    and at most the nominal's plus twice its sampling scatter √(2/N) (a calibration that fits the
    noise of a control is no better than the nominal model, and no worse beyond that scatter),
    the 95 % intervals' coverage, failed points."""
    splits = _splits(family)
    inside = sum(s["inside"] for s in splits)
    rows = sum(s["rows"] - s["failed"] for s in splits)
    scatter = [2.0 * np.sqrt(2.0 / max(s["rows"] - s["failed"], 1)) for s in splits]
    worse = [s for s in splits if not s["chi2_per_n_calibrated"] <= s["chi2_per_n_nominal"]]
    rules = {rule: {"coverage_95": sum(s["rules"][rule]["inside"] for s in splits) / max(rows, 1),
                    "chi2_per_n_predictive": sum(s["rules"][rule]["chi2_sum"] for s in splits) / max(rows, 1)}
             for rule in FIELD_RULES}
    return {"splits": len(splits),
            "better_than_nominal": int(sum(s["chi2_per_n_calibrated"] <= s["chi2_per_n_nominal"] for s in splits)),
            "not_worse_beyond_scatter": int(sum(s["chi2_per_n_calibrated"] <= s["chi2_per_n_nominal"] + d
                                                for s, d in zip(splits, scatter))),
            "coverage_95": inside / max(rows, 1), "failed_points": int(sum(s["failed"] for s in splits)),
            "chi2_per_n_predictive": rules["bound"]["chi2_per_n_predictive"], "field_rules": rules,
            # where the calibrated model is worse than the nominal one (χ²/N, noise only): how many of those
            # splits' points have intervals at least as wide as the nominal model's error there
            "worse_than_nominal_rows": int(sum(s["rows"] - s["failed"] for s in worse)),
            "worse_than_nominal_wider": int(sum(s["wider_than_nominal_misfit"] for s in worse))}


def publish(out: dict, n_seeds: int) -> str:
    """Write the figures for the documentation (``docs/validation/data/prediction.json``, with the date,
    the commit and the command: :mod:`publish`), so that the validation page's tables come from this run."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from publish import publish as write

    return write("prediction", {"summary": {e: out[e]["summary"] for e in ESTIMATORS},
                                "out_of_family": {e: out[e]["families"]["out_of_family"] for e in ESTIMATORS},
                                "wall_seconds": out.get("wall_seconds")},
                 f"python benchmarks/bench_prediction.py {n_seeds}")


def run(n_seeds: int = 12) -> dict:
    t0 = time.perf_counter()
    out = {}
    for est in ESTIMATORS:
        fam = {"out_of_family": out_of_family(est), "phase_vi": phase_vi(est),
               "prior_draws": {"twin_d": prior_draws(est, n_seeds)}}
        out[est] = {"families": fam, "summary": {k: summary(v) for k, v in fam.items()}}
        out[est]["summary"]["all"] = summary(fam)
        OUT.parent.mkdir(parents=True, exist_ok=True)
        (OUT.parent / "prediction.json").write_text(json.dumps(out, indent=1))      # each estimator as it ends
    out["wall_seconds"] = time.perf_counter() - t0
    OUT.parent.mkdir(parents=True, exist_ok=True)
    (OUT.parent / "prediction.json").write_text(json.dumps(out, indent=1))
    publish(out, n_seeds)
    return out


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    result = run(int(args[0]) if args else 12)
    print(json.dumps({k: v["summary"] for k, v in result.items() if k in ESTIMATORS}, indent=1))
