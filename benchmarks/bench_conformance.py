"""The conformance matrix: every supported combination of model kind, estimator, prior, executor
and noise model gives the right answer on synthetic data with a known truth (statistics, not speed).

The matrix, its truths and its pass rule are those of ``tests/conformance.py`` (the test suite runs
the same cells: a subset in ``make test``, all with ``pytest -m statistics``). This benchmark runs
every cell, prints one line per cell and publishes the table (which combinations ran, pass or fail,
the worst |z| of a non-field parameter, the NEES against its bound, the MAP's self-check, time) to
``docs/validation/data/conformance.json``, rendered on the validation page *Conformance*.

Run: ``python benchmarks/bench_conformance.py`` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
sys.path.insert(0, os.path.join(ROOT, "tests"))
sys.path.insert(0, HERE)

#: A statistical study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

KEYS = ("model", "estimator", "prior", "executor", "noise", "conditions")


def _markdown(rows: list[dict]) -> str:
    n_pass = sum(r["passed"] for r in rows)
    lines = [f"{n_pass} of {len(rows)} cells pass; a cell passes when the calibration ends `converged` with no "
             "failed point, every non-field parameter lies within 3 σ of its truth, the NEES of the whole scaled "
             "vector lies below the 99.9 % quantile of χ²(n), and the MAP's self-check is silent.", "",
             "| model | estimator | prior | executor | noise | conditions | pass | worst \\|z\\|<br>(parameter) | NEES /<br>bound |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        mark = "yes" if r["passed"] else "**no**"
        if r.get("status") == "refused":  # refused by design (ML noise with uncertain conditions): nothing to judge
            judged = "refused | –"
        else:
            judged = f"{r['worst_z']:.2f}<br>({r['worst_parameter']}) | {r['nees']:.1f} / {r['nees_bound']:.1f}"
        lines.append(f"| {' | '.join(r[k] for k in KEYS)} | {mark} | {judged} |")
    if any(r.get("status") == "refused" for r in rows):
        lines += ["", "*refused*: ML noise with uncertain conditions, refused by design with an error naming "
                  "`calibration.noise`; such a cell passes when the calibration refuses it."]
    failed = [r for r in rows if not r["passed"]]
    if failed:
        lines += ["", "Why the failing cells fail:", ""]
        lines += [f"- `{r['cell']}`: {r['why']}" for r in failed]
    return "\n".join(lines) + "\n"


def run(cells: list | None = None, progress=print) -> dict:
    """Run the matrix (or ``cells``); figures per cell and the count that passed. The whole matrix
    is published for the validation page (``docs/validation/data/conformance.json``)."""
    from conformance import matrix, run_cell
    from publish import command_line, publish

    whole = cells is None
    cells = matrix() if whole else cells
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="bench_conformance-") as tmp, warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*InitialUnknowns")
        for k, cell in enumerate(cells, start=1):
            try:
                r = run_cell(cell, Path(tmp))
            except Exception as exc:  # noqa: BLE001 - a cell that raises is a failed cell, the others go on
                r = {"cell": cell.id, **vars(cell), "passed": False, "why": f"{type(exc).__name__}: {exc}",
                     "worst_z": float("nan"), "worst_parameter": "-", "nees": float("nan"),
                     "nees_bound": float("nan"), "wall_s": float("nan")}
            r = {k: v for k, v in r.items() if k not in ("p_hat", "std_p", "names")}
            rows.append(r)
            progress(f"[conformance {k}/{len(cells)}] {cell.id}: {'pass' if r['passed'] else 'FAIL ' + r['why']} "
                     f"(worst |z| {r['worst_z']:.2f}, NEES {r['nees']:.1f}/{r['nees_bound']:.1f}, {r['wall_s']:.1f} s)")
    out = {"n_cells": len(rows), "n_passed": sum(r["passed"] for r in rows),
           "worst_z": max((r["worst_z"] for r in rows if r["worst_z"] == r["worst_z"]), default=float("nan")),
           "wall_s": time.perf_counter() - t0, "cells": rows}
    if out["n_passed"] < out["n_cells"]:
        out["error"] = f"{out['n_cells'] - out['n_passed']} of {out['n_cells']} cells fail"
    if whole:
        out["published"] = publish("conformance", out, command_line(), _markdown(rows))
    return out


def main() -> int:
    res = run()
    print(f"{res['n_passed']} of {res['n_cells']} cells pass in {res['wall_s']:.0f} s; wrote {res['published']}")
    return 0 if "error" not in res else 1


if __name__ == "__main__":
    sys.exit(main())
