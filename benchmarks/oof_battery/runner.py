"""Runner of the out-of-family battery: calib's diagnosis on every data set, verdicts tabulated.

For each (set-up, data set, seed) CSV of ``generate.py``, ``calib.diagnosis.command.run_diagnose``
(the code of ``calib diagnose --rotor nrel5mw --data CSV --config config_<set-up>.toml --out
DIR --no-history``) runs in one of at most two worker processes (each with one BLAS thread);
its ``diagnosis.json`` gives the verdict. A record per diagnosis is appended to
``verdicts.jsonl`` as it finishes, so an interrupted battery resumes where it stopped
(records are reused only for a data file with the same SHA-256 and the same config).

What counts as right (``campaign.DATA_SETS[...]["right"]``):

- control: the verdict is ``none``;
- an effect: the first verdict names one of the data set's right names, or is ``ambiguous``
  with one of them in the pair. The uniform table change ("polars at another Reynolds
  number", the same change on every section at every point) counts as right when named
  ``reynolds_number`` or ``leading_edge_erosion``: both of calib's models are a drag rise with
  a lift loss near stall, and data without a Reynolds-number dependence cannot tell polars
  taken at another Reynolds number from roughness on the whole blade (calib's erosion onset
  reaches down to r/R = 0.3).

``alone`` counts the right verdicts that name nothing else (no second physical effect; a model-form
parameter of the induction model, ``model_form`` in ``diagnosis.json``, is shown beside the verdict
and is not a second effect).

Verdict keys read from ``diagnosis.json``: ``effect``, ``effects``, ``rounds`` (``verdict``,
``reason``, candidates), ``before`` (χ²/dof, p), ``with_effects``, ``failure``.
"""

from __future__ import annotations

import collections
import json
import math
import multiprocessing
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from oof_battery import campaign  # noqa: E402

#: calib's candidate effects (for reading an ``ambiguous`` pair from a verdict's reason).
CANDIDATES = ("rotational_augmentation", "leading_edge_erosion", "pitch_offset", "reynolds_number", "tip_loss",
              "wind_tunnel_blockage", "wind_speed_scale", "lift_offset", "momentum_balance")
MAX_WORKERS = 2
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _sha256(path) -> str:
    from calib.measurements import sha256_of
    return sha256_of(path)


def diagnose_job(job: dict) -> dict:
    """Run one diagnosis (in a worker process) and return its record.

    Parameters
    ----------
    job : dict
        ``setup``, ``data_set``, ``seed``, ``csv``, ``config``, ``out`` (folder of the diagnosis).

    Returns
    -------
    dict
        The job's keys plus ``effect``, ``effects``, ``ambiguous``, ``rounds`` (per round:
        ``verdict``, ``reason``, the three best candidates with Λ, p, BIC, status, at_bound),
        ``chi2_per_dof_before``, ``p_before``, ``chi2_per_dof_with_effects``, ``failure``,
        ``seconds``; or ``error`` when the diagnosis raised.
    """
    from calib.diagnosis.command import run_diagnose

    rec = {k: job[k] for k in ("setup", "data_set", "seed", "csv", "config")}
    rec["sha256"], rec["config_sha256"] = _sha256(job["csv"]), _sha256(job["config"])
    lines: list[str] = []
    t0 = time.perf_counter()
    try:
        run_diagnose("nrel5mw", job["csv"], job["out"], config=job["config"], history=False, printer=lines.append)
    except Exception as exc:  # noqa: BLE001  (a crash is a result of the battery, not the end of it)
        rec.update(error=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0, log_tail=lines[-8:])
        return rec
    rec["seconds"] = time.perf_counter() - t0
    doc = json.loads((Path(job["out"]) / "diagnosis.json").read_text())
    rec.update(verdict_of(doc))
    return rec


def verdict_of(doc: dict) -> dict:
    """The battery's fields of one ``diagnosis.json``."""
    rounds = []
    for rnd in doc.get("rounds", []):
        cands = sorted(rnd.get("candidates", []), key=lambda c: c.get("bic", math.inf))[:3]
        rounds.append({"verdict": rnd.get("verdict"), "reason": rnd.get("reason", ""),
                       "ambiguous": rnd.get("ambiguous") or _pair(rnd), "shares": rnd.get("shares", []),
                       "best": [{"name": c.get("name"), "lr": c.get("lr_statistic"), "p": c.get("p_value"),
                                 "bic": c.get("bic"), "significant": c.get("significant"), "status": c.get("status"),
                                 "at_bound": c.get("at_bound", []),
                                 "values": {q["name"]: q["value"] for q in c.get("parameters", [])}} for c in cands]})
    ambiguous = next((r["ambiguous"] for r in rounds if r["verdict"] == "ambiguous"), [])
    before, with_fx = doc.get("before", {}), doc.get("with_effects", {})
    return {"effect": doc.get("effect"), "effects": list(doc.get("effects", [])),
            "model_form": list(doc.get("model_form", [])), "ambiguous": ambiguous,
            "rounds": rounds, "chi2_per_dof_before": before.get("chi2_per_dof"), "p_before": before.get("p_value"),
            "chi2_per_dof_with_effects": with_fx.get("chi2_per_dof"), "failure": doc.get("failure", "")}


def _pair(rnd: dict) -> list:
    """The two effects of an ``ambiguous`` round, read from its reason ("A and B fit about equally ...")."""
    if rnd.get("verdict") != "ambiguous":
        return []
    reason = rnd.get("reason", "")
    found = sorted((reason.find(n), n) for n in CANDIDATES if n in reason)
    return [n for _, n in found][:2]


def score(rec: dict) -> dict:
    """``right`` and ``alone`` (right, and no further effect named) of one record."""
    right_names = set(campaign.DATA_SETS[rec["data_set"]]["right"])
    if "error" in rec:
        return {"right": False, "alone": False, "first": "error"}
    effect = rec["effect"]
    if effect == "ambiguous":
        first = "ambiguous(" + "+".join(rec["ambiguous"]) + ")"
        right = bool(right_names & set(rec["ambiguous"]))
    else:
        first = effect
        right = effect in right_names
    # a model-form parameter (the induction model's) is no physical effect: it is neither the verdict nor a
    # further effect, and it is shown beside the verdict
    form = rec.get("model_form", [])
    physical = [e for e in rec["effects"] if e not in form]
    further = physical[1:] if effect != "ambiguous" else physical
    if form:
        first += " (model form: " + "+".join(form) + ")"
    return {"right": right, "alone": right and not further, "first": first}


def tabulate(records: list) -> dict:
    """Per (set-up, data set): counts, fractions, what was named, χ²/dof before, time per diagnosis."""
    groups = collections.defaultdict(list)
    for rec in records:
        groups[(rec["setup"], rec["data_set"])].append(rec)
    table = {}
    for setup in campaign.SETUPS:
        for ds in campaign.DATA_SETS:
            recs = groups.get((setup, ds), [])
            if not recs:
                continue
            sc = [score(r) for r in recs]
            named = collections.Counter(s["first"] for s in sc)
            full = collections.Counter("+".join(e + ("(model form)" if e in r.get("model_form", []) else "")
                                                for e in r["effects"]) if r.get("effects") else s["first"]
                                       for r, s in zip(recs, sc))
            chi2 = sorted(r["chi2_per_dof_before"] for r in recs if r.get("chi2_per_dof_before") is not None)
            table[f"{setup}/{ds}"] = {
                "setup": setup, "data_set": ds, "right_names": list(campaign.DATA_SETS[ds]["right"]),
                "n": len(recs), "right": sum(s["right"] for s in sc), "alone": sum(s["alone"] for s in sc),
                "right_fraction": sum(s["right"] for s in sc) / len(recs),
                "alone_fraction": sum(s["alone"] for s in sc) / len(recs),
                "named_first": dict(named.most_common()), "named_all": dict(full.most_common()),
                "errors": sum("error" in r for r in recs),
                "failures": sum(bool(r.get("failure")) for r in recs),
                "chi2_per_dof_before_median": chi2[len(chi2) // 2] if chi2 else None,
                "seconds_per_diagnosis": sum(r["seconds"] for r in recs) / len(recs)}
    return table


def markdown(table: dict) -> str:
    """The table as markdown: one row per (set-up, data set)."""
    rows = [("| set-up | data set | counts as right | right / total | alone | first verdicts | all named | "
             "χ²/dof before (median) | s / diagnosis |"), "|---|---|---|---|---|---|---|---|---|"]
    for row in table.values():
        # " + " between names, so that a cell of several names wraps between them on a narrow page
        named = ", ".join(f"{k.replace('+', ' + ')} {v}" for k, v in row["named_first"].items())
        full = ", ".join(f"{k.replace('+', ' + ')} {v}" for k, v in row["named_all"].items())
        chi2 = row["chi2_per_dof_before_median"]
        rows.append(f"| {row['setup']} | {row['data_set']} | {' or '.join(row['right_names'])} | "
                    f"{row['right']} / {row['n']} | {row['alone']} | {named} | {full} | "
                    f"{'' if chi2 is None else f'{chi2:.3g}'} | {row['seconds_per_diagnosis']:.1f} |")
    return "\n".join(rows) + "\n"


def _load(path: Path) -> list:
    if not path.exists():
        return []
    out = []
    for line in path.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except json.JSONDecodeError:      # a line cut by a kill
            continue
    return out


def run_battery(files: list, configs: dict, out: Path, workers: int = MAX_WORKERS, resume: bool = True,
                say=print) -> list:
    """Diagnose every ``(setup, data_set, seed, csv)`` of ``files``; returns the records.

    Parameters
    ----------
    files : list of tuple
        ``(setup, data_set, seed, csv path)`` (``generate.generate()["files"]``).
    configs : dict
        Set-up -> config TOML path.
    out : Path
        Folder of ``verdicts.jsonl`` and the diagnoses (``diag/<set-up>/<data set>_seed<k>``).
    workers : int
        Worker processes (at most :data:`MAX_WORKERS`).
    resume : bool
        Reuse the records of ``verdicts.jsonl`` whose data and config files are unchanged.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / "verdicts.jsonl"
    done = {}
    if resume:
        for rec in _load(log):
            done[(rec["setup"], rec["data_set"], rec["seed"], rec.get("sha256"), rec.get("config_sha256"))] = rec
    else:
        log.write_text("")
    records, jobs = [], []
    cfg_sha = {s: _sha256(p) for s, p in configs.items()}
    for setup, ds, seed, csv in files:
        key = (setup, ds, seed, _sha256(csv), cfg_sha[setup])
        if key in done:
            records.append(done[key])
            continue
        jobs.append({"setup": setup, "data_set": ds, "seed": seed, "csv": str(csv), "config": str(configs[setup]),
                     "out": str(out / "diag" / setup / f"{ds}_seed{seed}")})
    # the slow set-up first, so that the two workers end together
    jobs.sort(key=lambda j: (j["setup"] != "tilted", j["data_set"], j["seed"]))
    say(f"[oof battery] {len(jobs)} diagnoses to run on {workers} process(es); {len(records)} reused from {log}")
    if not jobs:
        return records
    for var in THREAD_VARIABLES:
        os.environ.setdefault(var, "1")
    t0 = time.perf_counter()
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=max(1, min(workers, MAX_WORKERS)), mp_context=ctx) as pool, \
            open(log, "a") as fh:
        futures = [pool.submit(diagnose_job, j) for j in jobs]
        for k, fut in enumerate(as_completed(futures), 1):
            rec = fut.result()
            records.append(rec)
            fh.write(json.dumps(rec) + "\n")
            fh.flush()
            s = score(rec)
            elapsed = time.perf_counter() - t0
            eta = elapsed / k * (len(jobs) - k)
            named = rec.get("error") or "+".join(rec.get("effects") or []) or rec.get("effect")
            say(f"[oof battery] {k}/{len(jobs)} {rec['setup']}/{rec['data_set']} seed {rec['seed']}: {named} "
                f"({'right' if s['right'] else 'WRONG'}; {rec['seconds']:.1f} s); elapsed {elapsed / 60:.1f} min, "
                f"left ~{eta / 60:.1f} min")
    return records
