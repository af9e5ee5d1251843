"""Campaign design on real sensors: which of the five Phase VI pressure-tap stations to add to the hub loads.

The data: ``workflows/phase_vi.toml`` (NREL Phase VI sequence H, six wind speeds 7-25 m/s at 72 rpm:
torque, thrust and the tap coefficients c_n, c_t at r/R = 0.30, 0.47, 0.63, 0.80, 0.95). The model:
the workflow's native BEM with the effect its diagnosis names (run once here), its prior and its
stated noise fractions.

1. *The design's choice.* :func:`calib.design.groups.subset_scores` scores every choice of k of the five
   stations (k = 1, 2, 3; the hub loads always): the held-out prediction variance of torque and thrust
   (one wind speed left out at a time, model plus the default discrepancy), and the D_s value of the
   parameters. The design picks the subset with the smallest held-out variance (the check below is a
   held-out prediction). Nothing measured enters this step.
2. *Realized.* Every subset's calibration (hub loads plus its taps) validated as the workflow validates
   it: :func:`calib.workflow.validation.leave_one_out` over the wind speeds, torque and thrust predicted at
   the speed left out. Score: the mean over torque and thrust of the mean |error| calibrated over the
   nominal model's (smaller is better).
3. *Agreement.* Per k, the design's pick against the median subset (a random choice of k stations is
   each subset with equal probability, so its median score is the median over subsets), and the
   Spearman rank correlation of the design's scores with the realized ones (over the 5, 10 and 10
   subsets).

4. *Four proxies* (pre-registered in the CHANGELOG before they were measured; no constant set from the
   realized ranking), each compared with the realized ranking as in 3 and against its noise
   (:func:`ranking_noise`):

   (a) ``variance``: the held-out prediction variance of step 1 (default discrepancy κ = 1);
   (b) ``variance_misfit``: the same with κ from the hub-only campaign's misfit, κ² = its held-out mean
       squared torque/thrust error over the design's noise variance, minus 1 (:func:`misfit_kappa`);
   (c) ``sequential``: the hub-only calibration's posterior as the prior, linearized at its MAP (``calib
       design --after``), the torque/thrust model output's variance after the stations' data alone
       (:func:`calib.design.groups.subset_sequential`, discrepancy at (b)'s κ);
   (d) ``heldout_error``: the expected held-out squared error of the calibration as it is run (no discrepancy)
       under a truth with the discrepancy at (b)'s κ, variance plus bias
       (:func:`calib.design.groups.subset_heldout_error`).

``python benchmarks/bench_design_phase_vi.py`` (27 leave-one-out validations of six folds each, one full
hub-only calibration).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from itertools import combinations

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, ROOT)

from calib.design import problem_from_workflow  # noqa: E402
from calib.calibration.calibrator import Calibrator  # noqa: E402
from calib.design.core import DEFAULT_DISCREPANCY  # noqa: E402
from calib.design.discrepancy import Discrepancy  # noqa: E402
from calib.design.groups import subset_heldout_error, subset_scores, subset_sequential  # noqa: E402
from calib.diagnosis.core import diagnose  # noqa: E402
from calib.diagnosis.in_workflow import named_effect_specs  # noqa: E402
from calib.measurements import read_measurements  # noqa: E402
from calib.workflow import load_workflow, prepare  # noqa: E402
from calib.workflow.validation import ValidationSettings, leave_one_out  # noqa: E402

SUITE = "validate"
WORKFLOW = os.path.join(ROOT, "workflows", "phase_vi.toml")
STATIONS = ("0.30", "0.47", "0.63", "0.80", "0.95")
HUB = ("torque", "thrust")
#: The pre-registered proxies (smaller is better for each), in the order of the CHANGELOG.
PROXIES = ("variance", "variance_misfit", "sequential", "heldout_error")
PROXY_WORDS = {"variance": "(a) held-out variance, κ = 1", "variance_misfit": "(b) held-out variance, κ from the misfit",
               "sequential": "(c) after the hub-only calibration", "heldout_error": "(d) held-out error, variance + bias"}


def misfit_kappa(hub_only: dict, sigma: dict) -> float:
    """The discrepancy's amplitude over the noise the hub-only campaign shows: κ² = the mean over torque and
    thrust of its held-out mean squared error over the design's noise variance σ_c², minus 1 (0 when the
    model is as good as the noise) [-]."""
    r = [np.mean([(f["measured"] - f["predicted"]) ** 2 for f in hub_only["folds"][ch]]) / sigma[ch] ** 2
         for ch in HUB]
    return float(np.sqrt(max(np.mean(r) - 1.0, 0.0)))


def hub_only_result(setup, meas, grid, effects, out_dir):
    """The hub-only calibration on every wind speed, saved as a result folder for ``after``."""
    res = Calibrator(setup.model(grid, list(HUB), None, effects), meas.select_channels(list(HUB)),
                     setup.calibration, name="hub loads").run()
    res.save(out_dir)
    return res


def tap_errors(setup, meas, grid, effects, p_hat) -> dict:
    """After the fact (the taps measured; no design proxy): each station's c_n and c_t RMS error over the
    measured RMS, of the nominal model and of the hub-only calibration's estimate ``p_hat``."""
    chans = [f"{q}@{s}" for s in STATIONS for q in ("cn", "ct")]
    model = setup.model(grid, chans, None, effects)
    y = meas.select_channels(chans).values
    rms = np.sqrt(np.mean(y ** 2, axis=0))
    err = {}
    for label, p in (("nominal", np.array([q.nominal for q in model.parameters], float)), ("hub_calibrated", p_hat)):
        ev = model.evaluate(np.asarray(p, float), meas.conditions)
        err[label] = (np.sqrt(np.mean((ev.values - y) ** 2, axis=0)) / rms).reshape(len(STATIONS), 2).tolist()
    return err


def proxy_scores(problem, after_problem, cond, kappa: float) -> dict:
    """Every proxy's score of every subset of k stations, k = 1, 2, 3: {k: {proxy: list}}."""
    misfit = Discrepancy(max(kappa, 1e-6), DEFAULT_DISCREPANCY.length)
    out = {}
    for k in (1, 2, 3):
        kw = {"always": HUB, "targets": HUB}
        out[k] = {
            "variance": [d["heldout_variance"] for d in subset_scores(problem, cond, k, discrepancy=DEFAULT_DISCREPANCY,
                                                                      **kw)],
            "variance_misfit": [d["heldout_variance"] for d in subset_scores(problem, cond, k, discrepancy=misfit,
                                                                             **kw)],
            "sequential": [d["target_variance"] for d in subset_sequential(after_problem, cond, k, discrepancy=misfit,
                                                                           **kw)],
            "heldout_error": [d["heldout_error"] for d in subset_heldout_error(problem, cond, k, discrepancy=misfit,
                                                                               **kw)]}
    return out


def spearman(a, b) -> float:
    """Spearman's rank correlation of two score lists (average ranks for ties) [-]."""
    from scipy.stats import spearmanr

    return float(spearmanr(a, b).statistic)


def realized(setup, meas, grid, effects, stations) -> dict:
    """Leave one wind speed out with the hub loads and the taps at ``stations``: torque and thrust."""
    chans = list(HUB) + [f"{q}@{s}" for q in ("cn", "ct") for s in stations]
    t = time.process_time()
    val = leave_one_out(lambda: setup.model(grid, chans, None, effects), meas.select_channels(chans),
                        setup.calibration, ValidationSettings("wind_speed", HUB))
    out = {"stations": list(stations), "cpu_s": time.process_time() - t}
    ratios = []
    for ch in HUB:
        s = val.summary(ch)
        out[ch] = {k: s[k] for k in ("mean_abs_error_calibrated", "mean_abs_error_nominal", "inside", "folds",
                                     "failed")}
        ratios.append(s["mean_abs_error_calibrated"] / s["mean_abs_error_nominal"])
    out["score"] = float(np.mean(ratios))
    statuses = {}
    for r in val.rows:
        if r.channel == HUB[0]:
            statuses[r.status] = statuses.get(r.status, 0) + 1
    out["statuses"] = statuses
    out["folds"] = {ch: [{"group": float(r.group), "measured": float(r.measured), "nominal": float(r.nominal),
                          "predicted": float(r.predicted)} for r in val.rows if r.channel == ch] for ch in HUB}
    print(f"[design-phase-vi] hub + taps {', '.join(stations) or 'none'}: torque "
          f"{out['torque']['mean_abs_error_calibrated']:.0f} N m, thrust {out['thrust']['mean_abs_error_calibrated']:.0f}"
          f" N (score {out['score']:.3f}, {out['cpu_s']:.0f} s CPU)", flush=True)
    return out


def _fold_errors(real: list) -> tuple[np.ndarray, np.ndarray]:
    """|error| calibrated, shape (subsets, channels, folds), and nominal, (channels, folds), of the held-out
    torque and thrust (the folds in the same order for every subset)."""
    cal = np.array([[[abs(f["measured"] - f["predicted"]) for f in r["folds"][ch]] for ch in HUB] for r in real])
    nom = np.array([[abs(f["measured"] - f["nominal"]) for f in real[0]["folds"][ch]] for ch in HUB])
    return cal, nom


def _scores(cal, nom, idx) -> np.ndarray:
    """The realized score of every subset from the folds ``idx`` (a resample): the mean over torque and
    thrust of the mean |error| calibrated over the nominal's."""
    return np.mean(cal[:, :, idx].mean(axis=-1) / nom[:, idx].mean(axis=-1), axis=1)


def ranking_noise(real: list, design_scores, n_boot: int = 2000, n_perm: int = 20000, seed: int = 39) -> dict:
    """How noisy the realized ranking is, and whether the design's agrees with it within that noise.

    The realized score of a subset rests on six held-out wind speeds. Resampling the folds with replacement
    (the same resample for every subset, Efron & Tibshirani 1993, ch. 6) gives:

    - ``ceiling``: Spearman between the realized scores and those of a resample, median and 5-95 %: how
      well a ranking that *is* the realized one agrees with a realization of it, the most any predicted
      ranking can expect;
    - ``design``: Spearman between the design's scores and a resample's realized ones, median and 5-95 %;
    - ``between_resamples``: Spearman between two independent resamples (both scatter, so lower than the
      ceiling; the ceiling compares with the data themselves and is optimistic);
    - ``p_permutation``: the chance that a ranking unrelated to the realized one reaches the observed Spearman
      (the design's scores permuted at random, ``n_perm`` permutations; one-sided);
    - ``p_below_ceiling``: the share of resamples whose ceiling Spearman is at or below the design's observed
      one: small means the design's ranking disagrees with the realized one beyond the folds' noise;
    - ``pick_best``, ``pick_at_least_median``: the share of resamples where the design's pick is the best subset,
      is at least as good as the median subset.
    """
    from scipy.stats import rankdata

    cal, nom = _fold_errors(real)
    n_f = cal.shape[-1]
    rng = np.random.default_rng(seed)
    score = _scores(cal, nom, np.arange(n_f))
    d = np.asarray(design_scores, float)
    obs = spearman(d, score)
    boot = np.array([_scores(cal, nom, rng.integers(0, n_f, n_f)) for _ in range(n_boot)])
    rb = rankdata(boot, axis=1)                                         # Spearman: Pearson of the ranks

    def rho(a, B):
        a, B = a - a.mean(), B - B.mean(axis=-1, keepdims=True)
        den = np.sqrt(np.sum(a * a) * np.sum(B * B, axis=-1))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sum(a * B, axis=-1) / den
    rd, rs = rankdata(d), rankdata(score)
    ceiling, design = rho(rs, rb), rho(rd, rb)
    pairs = np.array([rho(a, b) for a, b in zip(rb[0::2], rb[1::2])])
    perm = rho(rs, np.array([rng.permutation(rd) for _ in range(n_perm)]))
    pick = int(np.argmin(d))
    jack = np.array([_scores(cal, nom, np.delete(np.arange(n_f), f)) for f in range(n_f)])
    return {"observed": obs, "ceiling_median": float(np.median(ceiling)),
            "ceiling_5_95": np.percentile(ceiling, [5, 95]).tolist(),
            "between_resamples_median": float(np.median(pairs)),
            "between_resamples_5_95": np.percentile(pairs, [5, 95]).tolist(), "design_median": float(np.nanmedian(design)),
            "design_5_95": np.nanpercentile(design, [5, 95]).tolist(),
            "p_permutation": float(np.mean(perm >= rho(rs, rd) - 1e-12)),
            "p_below_ceiling": float(np.mean(ceiling <= obs + 1e-12)),
            "pick_best": float(np.mean(np.argmin(boot, axis=1) == pick)),
            "pick_at_least_median": float(np.mean(boot[:, pick] <= np.median(boot, axis=1))),
            "score_jackknife_sd": (np.sqrt((n_f - 1) / n_f * np.sum((jack - jack.mean(0)) ** 2, axis=0))).tolist(),
            "bootstraps": n_boot, "permutations": n_perm}


def run_bench() -> dict:
    workflow = load_workflow(WORKFLOW)
    setup = prepare(workflow)
    meas = read_measurements(os.path.join(workflow.base_dir, workflow.measurements.file), setup.channels)
    grid = setup.grid(meas.conditions)
    dset, _ = setup.diagnosis
    t = time.process_time()
    diag = diagnose(setup.rotor, meas, grid, setup.settings, setup.calibration, dset, rotor_source=setup.rotor_spec)
    effects = named_effect_specs(diag, skip=setup.nuisance)
    print(f"[design-phase-vi] diagnosis names {diag.effects} ({time.process_time() - t:.0f} s CPU)", flush=True)
    sensors = list(HUB) + [f"taps@{s}" for s in STATIONS]
    problem = problem_from_workflow(WORKFLOW, sensors=sensors, effects=effects)
    cond = meas.conditions
    t = time.process_time()
    design = {k: subset_scores(problem, cond, k, always=HUB, targets=HUB, discrepancy=DEFAULT_DISCREPANCY)
              for k in (1, 2, 3)}
    plain = {k: subset_scores(problem, cond, k, always=HUB, targets=HUB) for k in (1, 2, 3)}
    t_design = time.process_time() - t
    base = realized(setup, meas, grid, effects, ())
    every = realized(setup, meas, grid, effects, STATIONS)
    # what an engineer knows after the hub-load campaign: its calibration and its held-out misfit
    sigma = dict(zip(problem.channels, problem.sigma))
    kappa = misfit_kappa(base, sigma)
    with tempfile.TemporaryDirectory() as tmp:
        res = hub_only_result(setup, meas, grid, effects, tmp)
        after = problem_from_workflow(WORKFLOW, sensors=sensors, effects=effects, after=tmp)
    status = res.estimate.status
    taps = tap_errors(setup, meas, grid, effects, res.estimate.p_hat)
    t = time.process_time()
    proxies = proxy_scores(problem, after, cond, kappa)
    t_proxies = time.process_time() - t
    print(f"[design-phase-vi] misfit κ {kappa:.2f}; hub-only calibration {status}; proxies {t_proxies:.0f} s CPU",
          flush=True)
    out = {"named": list(diag.effects), "parameters": len(problem.names), "points": len(cond),
           "design_cpu_s": t_design, "hub_only": base, "all_five": every, "k": {},
           "misfit_kappa": kappa, "hub_only_status": status, "proxies_cpu_s": t_proxies,
           "sigma": {ch: float(sigma[ch]) for ch in HUB}, "tap_errors": taps}
    for k in (1, 2, 3):
        subsets = list(combinations(STATIONS, k))
        real = [realized(setup, meas, grid, effects, s) for s in subsets]
        score = np.array([r["score"] for r in real])
        var = np.array([d["heldout_variance"] for d in design[k]])
        ds = np.array([d["logdet"] for d in design[k]])
        var_plain = np.array([d["heldout_variance"] for d in plain[k]])
        pick = int(np.argmin(var))
        best = int(np.argmin(score))
        out["k"][str(k)] = {
            "subsets": [" + ".join(s) for s in subsets], "realized": real, "score": score.tolist(),
            "heldout_variance": var.tolist(), "ds_logdet": ds.tolist(), "heldout_variance_plain": var_plain.tolist(),
            "design_pick": " + ".join(subsets[pick]), "design_pick_score": float(score[pick]),
            "median_score": float(np.median(score)), "best": " + ".join(subsets[best]), "best_score": float(score[best]),
            "pick_rank": int(np.sum(score < score[pick])) + 1,
            "pick_at_least_median": bool(score[pick] <= np.median(score)),
            "spearman_heldout_variance": spearman(var, score), "spearman_ds": spearman(-ds, score),
            "spearman_heldout_variance_plain": spearman(var_plain, score),
            "noise": ranking_noise(real, var), "noise_ds": ranking_noise(real, -ds),
            "proxies": {name: proxy_summary(proxies[k][name], score, real) for name in PROXIES}}
    out["agrees_within_noise"] = {name: all(r["proxies"][name]["within_noise"] for r in out["k"].values())
                                  for name in PROXIES}
    return out


def proxy_summary(values, score, real) -> dict:
    """A proxy's scores, its pick, and its agreement with the realized ranking against that ranking's noise:
    within the noise when the observed Spearman is at or above the 5 % quantile of the realized ranking against
    its own resamples (the pre-registered rule)."""
    v = np.asarray(values, float)
    noise = ranking_noise(real, v)
    pick = int(np.argmin(v))
    return {"values": v.tolist(), "spearman": noise["observed"], "pick": pick, "pick_score": float(score[pick]),
            "pick_rank": int(np.sum(score < score[pick])) + 1, "noise": noise,
            "within_noise": bool(noise["observed"] >= noise["ceiling_5_95"][0] - 1e-12)}


def markdown(out: dict) -> str:
    rows = [f"NREL Phase VI sequence H ({out['points']} wind speeds), the workflow's model with the named effect "
            f"({', '.join(out['named']) or 'none'}; {out['parameters']} parameters). Score: the mean over torque and "
            "thrust of the held-out mean |error| calibrated over the nominal model's, one wind speed left out at a time "
            f"(hub loads alone {out['hub_only']['score']:.3f}, with all five stations {out['all_five']['score']:.3f}).",
            "", "| k | design's pick (r/R) | its score | median subset | best subset (score) | rank of the pick | "
            "Spearman: held-out variance, D_s |", "|---|---|---|---|---|---|---|"]
    for k, r in out["k"].items():
        rows.append(f"| {k} | {r['design_pick']} | {r['design_pick_score']:.3f} | {r['median_score']:.3f} | "
                    f"{r['best']} ({r['best_score']:.3f}) | {r['pick_rank']} of {len(r['score'])} | "
                    f"{r['spearman_heldout_variance']:.2f}, {r['spearman_ds']:.2f} |")
    rows += ["", "**How noisy the realized ranking is** (the six folds resampled with replacement, "
             f"{out['k']['1']['noise']['bootstraps']} resamples; Spearman of the design's held-out variance with the "
             "realized scores; the ceiling: the realized ranking against its own resamples; permutation p: the "
             "chance of the observed Spearman from a ranking unrelated to the realized one):", "",
             "| k | Spearman, observed | on resamples: median (5–95 %) | ceiling: median (5–95 %) | "
             "permutation p | resamples with the pick best, at least median |", "|---|---|---|---|---|---|"]
    for k, r in out["k"].items():
        q = r["noise"]
        rows.append(f"| {k} | {q['observed']:.2f} | {q['design_median']:.2f} ({q['design_5_95'][0]:.2f} to "
                    f"{q['design_5_95'][1]:.2f}) | {q['ceiling_median']:.2f} ({q['ceiling_5_95'][0]:.2f} to "
                    f"{q['ceiling_5_95'][1]:.2f}) | {q['p_permutation']:.2f} | {100 * q['pick_best']:.0f} %, "
                    f"{100 * q['pick_at_least_median']:.0f} % |")
    if "misfit_kappa" in out:
        rows += ["", f"**Four proxies, pre-registered** (the CHANGELOG's issue-39 section; κ from the hub-only "
                 f"campaign's misfit: {out['misfit_kappa']:.2f}). Each cell: Spearman with the realized scores, and "
                 "the rank of the proxy's pick; within the noise (✓) when the Spearman is at or above the 5 % quantile of "
                 "the realized ranking against its own resamples "
                 f"({', '.join(format(out['k'][k]['noise']['ceiling_5_95'][0], '.2f') for k in ('1', '2', '3'))} for "
                 "k = 1, 2, 3):", "", "| proxy | k = 1 (of 5) | k = 2 (of 10) | k = 3 (of 10) |", "|---|---|---|---|"]
        for name in PROXIES:
            cells = []
            for k in ("1", "2", "3"):
                q = out["k"][k]["proxies"][name]
                cells.append(f"{q['spearman']:.2f}{' ✓' if q['within_noise'] else ''}, pick {q['pick_rank']}")
            rows.append(f"| {PROXY_WORDS[name]} | " + " | ".join(cells) + " |")
    r1 = out["k"]["1"]
    rows += ["", "Single stations (k = 1): held-out prediction variance the design predicts [σ²] and the realized "
             "score:", "", "| station r/R | predicted variance | D_s | realized score | torque / thrust error [N m, N] |",
             "|---|---|---|---|---|"]
    for name, v, d, real in zip(r1["subsets"], r1["heldout_variance"], r1["ds_logdet"], r1["realized"]):
        rows.append(f"| {name} | {v:.3g} | {d:.1f} | {real['score']:.3f} | "
                    f"{real['torque']['mean_abs_error_calibrated']:.0f} / {real['thrust']['mean_abs_error_calibrated']:.0f} |")
    if "tap_errors" in out:
        rows += ["", "After the fact, not a design proxy (the taps measured): each station's c_n and c_t RMS error over "
                 "their measured RMS, the nominal model and the hub-only calibration's estimate, beside the realized "
                 "score with that station:", "", "| station r/R | c_n: nominal, hub-calibrated | c_t: nominal, "
                 "hub-calibrated | realized score |", "|---|---|---|---|"]
        te = out["tap_errors"]
        for i, (name, real) in enumerate(zip(r1["subsets"], r1["realized"])):
            (n_cn, n_ct), (h_cn, h_ct) = te["nominal"][i], te["hub_calibrated"][i]
            rows.append(f"| {name} | {n_cn:.2f}, {h_cn:.2f} | {n_ct:.2f}, {h_ct:.2f} | {real['score']:.3f} |")
    return "\n".join(rows) + "\n"


def run() -> dict:
    """Entry point of ``benchmarks/run_all.py``: the study, published for the validation page."""
    from publish import command_line, publish

    out = run_bench()
    publish("design_phase_vi", out, command_line(), markdown(out))
    return out


if __name__ == "__main__":
    print(markdown(run()))
