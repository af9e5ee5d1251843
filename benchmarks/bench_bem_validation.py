"""The native BEM against independent references, published for the validation page.

- IEA 3.4-MW: CCBlade's published steady performance table (50 rows), run with that table's
  set-up (precone, prebend, tilt 5 deg, shear exponent 0.2, 4 azimuth sectors, CCAirfoil's polar
  smoothing); and, to tell how much of the difference is the table's own, WISDEM's CCBlade run here
  at the same points with the same set-up (``bench_ccblade.iea34_table_points``, in ``.bench-venv``);
- NREL 5-MW: OpenFAST's steady operating points (5 m/s and above, same polars);
- NREL Phase VI: the measured low-speed-shaft torque of sequence H with the 2-D S809 polars.

The comparisons are the ones ``tests/test_bem_validation.py`` asserts bounds on; this module
writes their figures to ``docs/validation/data/native_bem.json``. ``python
benchmarks/bench_bem_validation.py`` (seconds, plus the CCBlade run: about a minute when its
environment exists, a few more to build it).
"""

from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(HERE), "tests"))

from test_bem_validation import iea34_comparison, nrel5mw_comparison, phase_vi_comparison  # noqa: E402

#: A validation study: run by `make validate` (benchmarks/run_all.py --suite validate), not `make bench`.
SUITE = "validate"

IEA34_LABELS = {"power": "aero power", "thrust": "thrust", "torque": "aero torque",
                "hub_flap_moment": "flap moment about the rotor centre",
                "root_flap_moment": "flap moment about the blade root"}


def _pct(x) -> float:
    return float(100 * x)


def iea34() -> dict:
    res, rel, below = iea34_comparison()
    _, rel_raw, _ = iea34_comparison(smoothing=None)
    out = {"points": int(below.size), "multiple_root_points": int(res.multiple_roots.sum()), "failed": int(res.n_failed),
           "quantities": {k: {"median_pct": _pct(np.median(np.abs(r))), "max_below_rated_pct":
                              _pct(np.abs(r[below]).max()), "max_above_rated_pct": _pct(np.abs(r[~below]).max())}
                          for k, r in rel.items()},
           "unsmoothed_power_first_rows_pct": [_pct(abs(x)) for x in rel_raw["power"][below][:3]],
           "unsmoothed_power_other_rows_below_rated_max_pct": _pct(np.abs(rel_raw["power"][below][3:]).max())}
    try:
        from bench_ccblade import ensure_env, iea34_table_points

        env = ensure_env()
        out["ccblade_run"] = {"iea34_error": env["error"]} if "error" in env else iea34_table_points()
    except Exception as exc:  # noqa: BLE001  (the CCBlade run is a cross-check; its failure is stated)
        out["ccblade_run"] = {"iea34_error": f"{type(exc).__name__}: {exc}"}
    return out


def nrel5mw() -> dict:
    res, dp, dt, ws, region2 = nrel5mw_comparison()
    return {"failed": int(res.n_failed), "rows": [
        {"wind_speed": float(v), "region": 2 if r2 else 3, "power_pct": _pct(p), "thrust_pct": _pct(t)}
        for v, p, t, r2 in zip(ws, dp, dt, region2)]}


def phase_vi() -> dict:
    res, meas = phase_vi_comparison()
    return {"failed": int(res.n_failed), "rows": [
        {"wind_speed": float(v), "measured": float(m), "native": float(b), "multiple_roots": bool(multi)}
        for v, m, b, multi in zip(meas["wind_speed"], meas["lss_torque"], res.torque, res.multiple_roots)]}


def markdown(f: dict) -> str:
    i = f["iea34"]
    lines = ["### IEA 3.4-MW against CCBlade's steady table", "",
             f"{i['points']} rows; |relative difference| native − table [%]:", "",
             "| quantity | median | max below rated | max above rated |", "|---|---|---|---|"]
    for k, q in i["quantities"].items():
        lines.append(f"| {IEA34_LABELS[k]} | {q['median_pct']:.2f} | {q['max_below_rated_pct']:.2f} | "
                     f"{q['max_above_rated_pct']:.2f} |")
    lines += ["", f"{i['multiple_root_points']} of {i['points']} points have a section with several roots of the "
                  "BEM residual (the smallest-φ root is kept and the point flagged). Without CCAirfoil's polar "
                  "smoothing the first rows below rated differ in power by "
                  + ", ".join(f"{x:.2f}" for x in i["unsmoothed_power_first_rows_pct"])
                  + f" %, the other rows below rated by at most {i['unsmoothed_power_other_rows_below_rated_max_pct']:.2f} %."]
    cc = i.get("ccblade_run", {})
    if "iea34_error" in cc:
        lines += ["", f"WISDEM's CCBlade could not be run at the same points in this run: {cc['iea34_error']}"]
    else:
        lines += ["", f"WISDEM's CCBlade, run at the same {cc['iea34_points_compared']} points with the same set-up "
                      "(median / max below rated / max above rated, %):", "",
                  "| | power | thrust |", "|---|---|---|"]
        for key, label in (("ccblade_vs_table", "CCBlade run here − table"), ("native_vs_ccblade", "native − CCBlade run here")):
            cells = []
            for q in ("power", "thrust"):
                cells.append(" / ".join(f"{cc[f'iea34_{key}_{q}_{s}_pct']:.2f}"
                                        for s in ("median", "max_below_rated", "max_above_rated")))
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", "### NREL 5-MW against OpenFAST's steady operating points", "",
              "Relative difference native − OpenFAST [%] at OpenFAST's rotor speed and pitch:", "",
              "| wind speed [m/s] | region | aero power | thrust |", "|---|---|---|---|"]
    for r in f["nrel5mw"]["rows"]:
        lines.append(f"| {r['wind_speed']:.1f} | {r['region']} | {r['power_pct']:+.2f} | {r['thrust_pct']:+.2f} |")
    lines += ["", "### NREL Phase VI, sequence H (measured)", "",
              "| wind speed [m/s] | measured LSS torque [N m] | native BEM [N m] | ratio |", "|---|---|---|---|"]
    for r in f["phase_vi"]["rows"]:
        flag = " (flagged: several roots)" if r["multiple_roots"] else ""
        lines.append(f"| {r['wind_speed']:.0f} | {r['measured']:.1f} | {r['native']:.1f} | "
                     f"{r['native'] / r['measured']:.2f}{flag} |")
    return "\n".join(lines) + "\n"


def run() -> dict:
    """Entry point of ``benchmarks/run_all.py``: the three comparisons, published for the validation page."""
    from publish import command_line, publish

    figures = {"iea34": iea34(), "nrel5mw": nrel5mw(), "phase_vi": phase_vi()}
    publish("native_bem", figures, command_line(), markdown(figures))
    return figures


if __name__ == "__main__":
    print(markdown(run()))
