"""What ``calib design`` writes: the test matrix in run order, the predicted posterior σ of every
parameter, the marginal-gain curve, the value of each sensor group, and a plain-words paragraph."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from calib.design.select import precision
from calib.report.atomic import atomic_write_text

__all__ = ["matrix_rows", "parameter_rows", "group_values", "summary", "paragraph", "write_outputs", "write_choice"]


def matrix_rows(res) -> list[dict]:
    """The test matrix: one row per distinct point in run order, with its repeats and sensors."""
    c, pr = res.candidates, res.problem
    lam = c.tip_speed_ratio(pr.envelope.radius)
    counts = dict(zip(*np.unique(res.design, return_counts=True)))
    fixed = set(res.fixed.tolist())
    cover = set(res.cover.tolist())
    sensors = " + ".join(g.name for g in pr.groups)
    added = {int(j): k + 1 for k, j in enumerate(res.design)}
    rows = []
    for k, j in enumerate(res.run_order()):
        rows.append({"run": k + 1, "wind_speed [m/s]": float(c.wind_speed[j]),
                     "rotor_speed [rpm]": float(c.rotor_speed[j]), "pitch [deg]": float(c.pitch[j]), "tsr [-]": float(lam[j]), "yaw [deg]": float(c.yaw[j]),
                     "air_density [kg/m^3]": float(c.air_density[j]), "sensors": sensors,
                     "channels": " ".join(pr.channels), "repeats": int(counts[j]),
                     "fixed": "cover" if j in cover else "yes" if j in fixed else "no", "candidate": int(j) + 1,
                     "chosen_as": added[int(j)]})
    return rows


def parameter_rows(res) -> list[dict]:
    """Predicted posterior 1-σ of every parameter: prior, design, full candidate set, space-filling design."""
    return [{"parameter": n, "sigma_prior": float(a), "sigma_design": float(b), "sigma_full_set": float(c),
             "sigma_space_filling": float(d), "ratio_design_to_prior": float(b / a) if a > 0 else float("nan")}
            for n, a, b, c, d in zip(res.problem.names, res.sigma_prior, res.sigma_design, res.sigma_full,
                                     res.sigma_uniform)]


def group_values(res) -> list[dict]:
    """Each sensor group's share of the design's information: log det A at the design with every group
    minus without this one, and that per unit cost; empty with one group."""
    pr = res.problem
    if len(pr.groups) < 2:
        return []
    full = float(np.linalg.slogdet(precision(res.H, res.design))[1])
    out = []
    for g in pr.groups:
        keep = [k for k, ch in enumerate(pr.channels) if not any(ch == c for c in g.channels)]
        without = float(np.linalg.slogdet(precision(res.H[:, keep, :], res.design))[1])
        out.append({"group": g.name, "channels": " ".join(g.channels), "cost_per_point": g.cost,
                    "logdet_loss_without": full - without, "loss_per_cost": (full - without) / g.cost})
    return out


def summary(res) -> dict:
    """The numbers of the design, JSON-ready."""
    pr, sel = res.problem, res.selection
    nd = res.n_determined
    n = len(res.design)
    gains = sel.greedy_gains
    k_next = n - res.fixed.size
    curve = res.logdet_curve
    # the next point's gain of the parameters' log det along the greedy order (the criterion's own gain
    # when the curve is short); with a discrepancy the criterion's gain also counts its coefficients
    nxt = (float(curve[k_next] - curve[k_next - 1]) if 1 <= k_next < curve.size
           else float(gains[k_next]) if gains.size > k_next else None)
    return {"workflow": pr.source, "criterion": res.criterion, "prior": pr.prior_from, "budget": n,
            "candidates": int(len(res.ok)), "candidates_failed": res.n_failed, "fixed": int(res.fixed.size),
            "distinct_points": int(np.unique(res.design).size), "envelope": pr.envelope.words(),
            "sensor_groups": [{"name": g.name, "channels": list(g.channels), "cost": g.cost} for g in pr.groups],
            "noise_sigma": dict(zip(pr.channels, map(float, pr.sigma))), "parameters": len(pr.names),
            "determined_directions": nd, "logdet": res.logdet, "gain_fraction_of_full": res.gain_fraction(),
            "next_point_gain": nxt, "next_point_gain_percent": (100 * nxt / res.logdet["design"]
                                                                 if nxt is not None and res.logdet["design"] > 0
                                                                 else None),
            "greedy_gains": gains.tolist(), "greedy_order": [int(j) + 1 for j in sel.greedy_order],
            "logdet_curve": res.logdet_curve.tolist(), "points_for_90_percent_of_full": _points_for(res, 0.9),
            "bound_share_of_full": (res.logdet["bound"] / res.logdet["full"] if "bound" in res.logdet
                                    and res.logdet["full"] > 0 else None),
            "exchanges": sel.exchanges, "exchange_passes": sel.passes,
            "cpu_seconds": res.seconds, "notes": pr.notes, "group_values": group_values(res),
            "robustness": res.robustness}


def _points_for(res, share: float):
    """Points of the greedy sequence after which the parameters' log det reaches ``share`` of the full
    set's (None if the curve does not reach it)."""
    c = res.logdet_curve
    if not c.size or not res.logdet["full"] > 0 or not np.any(c >= share * res.logdet["full"]):
        return None
    return int(res.fixed.size + np.argmax(c >= share * res.logdet["full"]) + 1)


def paragraph(res) -> str:
    """The design in plain words, from the numbers."""
    s = summary(res)
    nd, n = s["determined_directions"], s["budget"]
    pitches = np.unique(np.round(res.candidates.pitch[res.design], 3))
    words = [f"{n} points ({s['distinct_points']} distinct) on {pitches.size} pitch line(s) "
             f"({', '.join(f'{p:g}' for p in pitches[:8])}{' …' if pitches.size > 8 else ''} deg), chosen by "
             f"{res.criterion} from {s['candidates'] - s['candidates_failed']} candidates, determine {nd['design']} of the "
             f"{nd['full']} directions the full candidate set would (s > 1 against {s['prior']}); a space-filling "
             f"design of the same size determines {nd['uniform']}."]
    if res.logdet["full"] > 0:
        words.append(f"They carry {100 * s['gain_fraction_of_full']:.0f} % of the full set's information "
                     f"(log det {res.logdet['design']:.1f} of {res.logdet['full']:.1f}; space-filling "
                     f"{res.logdet['uniform']:.1f}).")
        if s["bound_share_of_full"] is not None:
            words.append(f"No design of {n} points can carry more than {100 * s['bound_share_of_full']:.0f} % (a "
                         "bound from the continuous relaxation).")
        n90 = s["points_for_90_percent_of_full"]
        words.append(f"90 % of the full set's information takes {n90} points in the greedy order." if n90 else
                     f"The greedy curve ({res.logdet_curve.size + res.fixed.size} points) does not reach 90 % of "
                     "the full set's information.")
    if s["next_point_gain_percent"] is not None:
        words.append(f"Point {n + 1} would add {s['next_point_gain_percent']:.1f} % to the design's log det.")
    ratio = res.sigma_design / np.where(res.sigma_prior > 0, res.sigma_prior, np.inf)
    tight = int(np.sum(ratio < 0.5))
    words.append(f"{tight} of {len(ratio)} parameters end with a σ below half their prior's.")
    rb = res.robustness
    if rb:
        words.append(f"Averaged over the linearization point and {rb['draws']} prior draws of the correction field "
                     f"(pseudo-Bayesian), the design shares {100 * rb['shared_points_mean']:.0f} % of its points "
                     f"(at least {100 * rb['shared_points_min']:.0f} %) with the optimum at each draw and loses "
                     f"{-rb['averaged_design_loss_mean']:.2g} of log det against it on average (worst "
                     f"{-rb['averaged_design_loss_worst']:.2g}); the design for the nominal field alone loses "
                     f"{-rb['nominal_design_loss_mean']:.2g} (worst {-rb['nominal_design_loss_worst']:.2g}).")
    gv = s["group_values"]
    if gv:
        best = max(gv, key=lambda g: g["loss_per_cost"])
        words.append(f"Per unit cost the {best['group']} group carries the most information "
                     f"({best['loss_per_cost']:.2g} of log det per unit).")
    if s["candidates_failed"]:
        words.append(f"The model failed at {s['candidates_failed']} candidates, left out.")
    return " ".join(words)


def _csv(rows, comment) -> str:
    """``rows`` (dicts with the same keys) as CSV under a ``# comment`` line; floats to 8 digits."""
    buf = io.StringIO()
    buf.write(f"# {comment}\n")
    out = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
    out.writeheader()
    out.writerows({k: format(v, ".8g") if isinstance(v, float) else v for k, v in r.items()} for r in rows)
    return buf.getvalue()


def write_outputs(res, out) -> list[Path]:
    """test_matrix.csv, parameters.csv, design.json, design.png, gain.png and report.md into ``out``."""
    from calib.design.figures import design_figure, gain_figure
    from calib.report.figures import save_figure

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    s = summary(res)
    paths = [atomic_write_text(out / "test_matrix.csv", _csv(matrix_rows(res), f"calib design, {res.criterion}, "
                                                             f"run order; {s['workflow']}")),
             atomic_write_text(out / "parameters.csv", _csv(parameter_rows(res), "predicted posterior 1-sigma "
                                                            "[parameter units]")),
             atomic_write_text(out / "design.json", json.dumps({**s, "test_matrix": matrix_rows(res),
                                                                "parameters": parameter_rows(res)}, indent=1))]
    paths.append(save_figure(design_figure(res), out, "design", formats=("png",))["png"])
    paths.append(save_figure(gain_figure(res), out, "gain", formats=("png",))["png"])
    lines = ["# Campaign design", "", paragraph(res), "", f"Envelope: {s['envelope']}. Noise 1-σ: "
             + ", ".join(f"{c} {v:.4g}" for c, v in s["noise_sigma"].items()) + ".", ""]
    lines += [f"- {n}" for n in s["notes"]]
    lines += ["", "![design](design.png)", "", "![marginal gain](gain.png)", "",
              "| run | λ | pitch [deg] | wind speed [m/s] | rotor speed [rpm] | repeats |", "|---|---|---|---|---|---|"]
    lines += [f"| {r['run']} | {r['tsr [-]']:.3g} | {r['pitch [deg]']:.3g} | {r['wind_speed [m/s]']:.3g} | "
              f"{r['rotor_speed [rpm]']:.4g} | {r['repeats']} |" for r in matrix_rows(res)]
    paths.append(atomic_write_text(out / "report.md", "\n".join(lines) + "\n"))
    return paths


def write_choice(choice: dict, out) -> Path:
    """``sensor_choice.csv``: every choice of k optional sensor groups, ranked by the held-out prediction
    variance of the always-measured channels [their noise variances] (``calib design --choose``)."""
    return atomic_write_text(Path(out) / "sensor_choice.csv", _csv(choice["rows"], (
        f"calib design --choose {choice['k']}: groups added to {' + '.join(choice['always'])}, ranked by the held-out "
        f"prediction variance of {' '.join(choice['targets'])} [noise variances] at the design's {choice['points']} "
        "points, one wind speed left out at a time; ds_logdet: information on the parameters")))
