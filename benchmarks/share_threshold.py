"""The later-effect share threshold from development diagnoses (issue 37): the rule stated in
CHANGELOG.md (committed in f3a43c1 before the shares were measured) applied to the decisions on a
share that the lifting-line battery's diagnoses recorded (``shares`` in each round of
``diagnosis.json``, kept in the battery's ``verdicts.jsonl``), plus the CCBlade stand-ins measured
on seeds 25000-25019 before the records existed.

Run: ``python benchmarks/share_threshold.py OUT.json VERDICTS.jsonl ...`` (the development batteries'
``verdicts.jsonl``, e.g. ``bench_output/lifting_line_battery/{default,fast_wake}_26000/verdicts.jsonl``
of ``bench_lifting_line_battery.py 20 26000``). Writes every decision (labelled true or stand-in) and the
balanced threshold to OUT.json; ``tests/test_diagnosis_share.py`` checks that
:data:`calib.diagnosis.naming.LATER_EFFECT_SHARE` is the rule's threshold on the committed records.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

from oof_battery import campaign, runner  # noqa: E402

#: The diagnosis's significance (``DiagnosisSettings.significance``) the batteries ran at [-].
ALPHA = 0.01
#: The CCBlade stand-ins of the out-of-family battery (rigid, seeds 25000-25019; CHANGELOG "the out-of-method
#: floor"): second effects named after rotational augmentation by the point share then (a later effect: a test
#: decision now). Their Λ and excess were recorded as ranges only (Λ 30-40 of χ² − dof 61-73, 252 residuals):
#: each is taken with excess 67 (the middle), one parameter, 250 dof, 6 physical candidates.
CCBLADE_STAND_INS = ((0.49, "lift_offset", 25009), (0.51, "lift_offset", 25010), (0.54, "reynolds_number", 25012))


def decisions(logs) -> list:
    """Every decision on a share in the records of ``logs`` (``verdicts.jsonl`` files), labelled ``true``
    when the candidate is one of its data set's right names and no right name was named in an earlier round
    (the data hold one effect: the uniform table's second right name after the first is a stand-in); a
    decision recorded identically in two rounds (the same fit weighed again) once."""
    out = []
    for log in logs:
        for rec in runner._load(Path(log)):
            seen, right = set(), campaign.DATA_SETS[rec["data_set"]]["right"]
            for k, rnd in enumerate(rec.get("rounds", [])):
                found = any(r["verdict"] in right for r in rec["rounds"][:k])
                for s in rnd.get("shares", []):
                    key = (s["candidate"], round(s["lr"], 6), round(s["chi2_base"], 6), s["decision"])
                    if key in seen:
                        continue
                    seen.add(key)
                    out.append({**s, "true": s["effect"] in right and not found,
                                "where": f"{Path(log).parent.name}/{rec['data_set']}/seed {rec['seed']}/round {k + 1}"})
    return out


def ccblade_stand_ins() -> list:
    """:data:`CCBLADE_STAND_INS` as decisions."""
    return [{"candidate": effect, "effect": effect, "lr": share * 67.0, "n_params": 1, "chi2_base": 250.0 + 67.0,
             "dof_base": 250, "n_candidates": 6, "decision": "test", "share": share, "true": False,
             "where": f"CCBlade rigid rotational_augmentation/seed {seed}"} for share, effect, seed in CCBLADE_STAND_INS]


def main(out: str, logs: list) -> dict:
    from calib.diagnosis.share import balanced_threshold, share_test

    recs = decisions(logs) + ccblade_stand_ins()
    true = [r for r in recs if r["true"]]
    stand = [r for r in recs if not r["true"]]
    rule = balanced_threshold(true, stand, ALPHA)
    for r in sorted(recs, key=lambda r: r["share"]):
        sd = share_test(r["lr"], r["n_params"], r["chi2_base"], r["dof_base"], min(max(r["share"], 0.01), 0.99),
                        ALPHA).sd
        print(f"{'true ' if r['true'] else 'stand'} {r['decision']:5s} {100 * r['share']:6.1f} % ± {100 * sd:4.1f}  "
              f"{r['effect']:24s} {r['where']}  (Λ {r['lr']:.4g}, χ² − dof {r['chi2_base'] - r['dof_base']:.4g})")
    for t, m, f in rule["curve"]:
        print(f"t {t:.2f}: miss {100 * m:.2f} %, false {100 * f:.2f} %")
    print(f"{len(true)} true decisions, {len(stand)} stand-ins; balanced at t = {rule['exact']:.3f} (miss "
          f"{100 * rule['miss']:.2f} %, false {100 * rule['false']:.2f} %): threshold {rule['threshold']:.2f}")
    doc = {"provenance": f"benchmarks/share_threshold.py on {', '.join(str(x) for x in logs)} (the rule of CHANGELOG, "
                         "issue 37; significance 0.01)", "alpha": ALPHA, "threshold": rule["threshold"],
           "exact": rule["exact"], "miss": rule["miss"], "false": rule["false"], "decisions": recs}
    Path(out).write_text(json.dumps(doc, indent=1) + "\n")
    return doc


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2:])
