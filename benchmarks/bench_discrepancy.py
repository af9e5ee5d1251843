"""How often the diagnosis names the right effect, over noise seeds (statistics).

For every effect of the library (truth values of ``tests/test_diagnosis.py``) and for a
control without effect: NREL 5-MW, 36 operating points (λ 3–11 × pitch −1…8 deg), power,
thrust, root flap moment and the normal force per length at r/R = 0.95, 1 % noise; seeds
9500 + k (none used by the tests). Figures: the fraction named right (``none`` for the
control), what else was named, and the time per diagnosis. ``python benchmarks/bench_discrepancy.py
[seeds]`` (2.7-16 s per diagnosis on the idle 2-core machine, one seed: tip loss, wind-speed scale and
blockage 11-16 s, the others under 4 s; 20 seeds: 180 diagnoses, about 24 min); ``make validate`` runs
it with 20 seeds. Publishes its table for the validation page
(``docs/validation/data/diagnosis_in_family.json``).
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests"))

from test_diagnosis import TRUTH, campaign, hidden  # noqa: E402
from test_diagnosis import run as diagnose_data  # noqa: E402

from calib.rotor.library import load_rotor  # noqa: E402

#: A statistical or soak study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"


def run_bench(n_seeds: int = 3) -> dict:
    rotor = load_rotor("nrel5mw")
    cond = campaign(rotor)
    out = {}
    for effect in ["none"] + sorted(TRUTH):
        named, t0 = Counter(), time.perf_counter()
        for k in range(n_seeds):
            meas = hidden({} if effect == "none" else {effect: TRUTH[effect]}, cond, 9500 + k)
            d = diagnose_data(meas, recalibrate=False)
            named[d.named_first] += 1       # a model-form parameter (tip_loss, momentum_balance) is named as such
            print(f"[discrepancy] truth {effect}, seed {9500 + k}: named {d.named_first}"
                  + (f" (model form: {', '.join(d.model_form)})" if d.model_form else ""), flush=True)
        out[effect] = {"right": named[effect] / n_seeds, "named": dict(named), "seeds": n_seeds,
                       "seconds_per_diagnosis": (time.perf_counter() - t0) / n_seeds}
    return out


def markdown(out: dict) -> str:
    """One row per hidden effect: how often it was named, what else was, the time per diagnosis."""
    n = next(iter(out.values()))["seeds"]
    rows = [f"NREL 5-MW, 36 operating points (λ 3–11 × pitch −1…8°), power, thrust, root flap moment and the "
            f"normal force per length at r/R 0.95, 1 % noise, {n} noise seeds per effect (seeds 9500–{9500 + n - 1}, "
            "none used by the tests).", "",
            "| hidden effect | named right | what was named | s / diagnosis |", "|---|---|---|---|"]
    for effect, r in out.items():
        right = round(r["right"] * r["seeds"])
        named = ", ".join(f"`{k}` {v}" for k, v in sorted(r["named"].items(), key=lambda kv: -kv[1]))
        label = "none (control)" if effect == "none" else effect
        rows.append(f"| {label} | {right} of {r['seeds']} | {named} | {r['seconds_per_diagnosis']:.1f} |")
    return "\n".join(rows) + "\n"


def run(n_seeds: int = 20) -> dict:
    """Entry point of ``benchmarks/run_all.py``: the study, published for the validation page."""
    from publish import command_line, publish

    out = run_bench(n_seeds)
    publish("diagnosis_in_family", {"n_seeds": n_seeds, "effects": out}, command_line(), markdown(out))
    return out


if __name__ == "__main__":
    import json

    print(json.dumps(run(int(sys.argv[1]) if len(sys.argv) > 1 else 20), indent=1))
