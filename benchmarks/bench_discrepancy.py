"""How often the discrepancy workflow names the right effect, over noise seeds (statistics).

For every effect of the library (truth values of ``tests/test_discrepancy.py``) and for a
control without effect: NREL 5-MW, 36 operating points (λ 3–11 × pitch −1…8 deg), power,
thrust, root flap moment and the normal force per length at r/R = 0.95, 1 % noise; seeds
9500 + k (none used by the tests). Figures: the fraction named right (``none`` for the
control), what else was named, and the time per diagnosis. ``python benchmarks/bench_discrepancy.py
[seeds]`` (2.7-16 s per diagnosis on the idle 2-core machine, one seed: tip loss, wind-speed scale and
blockage 11-16 s, the others under 4 s; 20 seeds: 180 diagnoses); ``make bench`` runs it with 3 seeds.
"""

from __future__ import annotations

import os
import sys
import time
from collections import Counter

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests"))

from test_discrepancy import TRUTH, campaign, hidden  # noqa: E402
from test_discrepancy import run as diagnose_data  # noqa: E402

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
            named[d.effect] += 1
            print(f"[discrepancy] truth {effect}, seed {9500 + k}: named {d.effect}", flush=True)
        out[effect] = {"right": named[effect] / n_seeds, "named": dict(named), "seeds": n_seeds,
                       "seconds_per_diagnosis": (time.perf_counter() - t0) / n_seeds}
    return out


def run(n_seeds: int = 3) -> dict:
    """Entry point of ``benchmarks/run_all.py``."""
    return run_bench(n_seeds)


if __name__ == "__main__":
    import json

    print(json.dumps(run_bench(int(sys.argv[1]) if len(sys.argv) > 1 else 3), indent=1))
