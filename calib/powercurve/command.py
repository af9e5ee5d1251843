"""``calib powercurve RESULT_DIR``: the calibrated model's power curve and AEP with their uncertainty.

Writes into ``--out`` (default ``RESULT_DIR/powercurve``): ``powercurve.csv`` / ``.json`` (per IEC
bin: power, C_P, C_T, thrust, rotor speed, pitch; central, nominal, the draws' and the delta
method's 1-σ, the draws' 5–95 % band, the budget), ``aep.csv`` / ``.json`` (per wind distribution:
P50, P90, 1-σ per source), the figures ``powercurve.png``, ``cp_tsr.png``, ``aep.png`` and
``report.md`` whose first paragraph it also prints. No open power-curve exchange format is followed
(none was found with uncertainty columns); the CSV columns carry their units in their names.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.powercurve.aep import IEC_RAYLEIGH_MEANS, rayleigh_cdf, weibull_cdf
from calib.powercurve.curve import CalibratedPowerCurve, calibrated_power_curve, iec_bins
from calib.powercurve.measurement import parse_measurement
from calib.powercurve.schedule import FixedSpeed, VariableSpeed, schedule_from_table
from calib.powercurve.statements import delta_statement, sampling_statement
from calib.report.atomic import atomic_path, atomic_write_text

__all__ = ["add_powercurve_arguments", "add_powercurve_parser", "parse_wind", "run_powercurve", "summary_paragraph",
           "write_outputs"]

DESCRIPTION = ("The power curve of the model a calibration produced, with intervals: the operating schedule "
               "(the rotor's variable-speed pitch-regulated schedule, a fixed speed and pitch, or a table) is "
               "re-solved for every posterior draw of the calibrated parameters (Gaussian, from the Laplace "
               "covariance, clipped to the bounds); beside the draws, the delta method. IEC 61400-12-1 bins, "
               "AEP for Rayleigh mean wind speeds 4-11 m/s, an optional Weibull and a measured histogram, with P50, P90 and the "
               "1-sigma of each source (calibration, model discrepancy, stated measurement items). Writes "
               "tables (CSV, JSON), figures and report.md; prints its first paragraph.")


def add_powercurve_parser(sub):
    """The ``powercurve`` subcommand's parser, added to ``sub`` (argparse subparsers)."""
    p = sub.add_parser("powercurve", help="the calibrated power curve and AEP, with their uncertainty",
                       description=DESCRIPTION)
    add_powercurve_arguments(p)
    return p


def add_powercurve_arguments(p) -> None:
    p.add_argument("result_dir", help="folder holding result.json and result.npz (a stage folder of 'calib run')")
    p.add_argument("--wind", default="3:25:0.5", help="bins START:STOP:STEP [m/s] (default 3:25:0.5)")
    p.add_argument("--density", type=float, default=1.225, help="reference air density [kg/m^3] (default 1.225)")
    p.add_argument("--draws", type=int, default=1000, help="posterior draws (default 1000; 0: delta method only)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the draws (default 0)")
    p.add_argument("--schedule", default="rotor", help="'rotor' (the rotor's variable-speed schedule, default), "
                   "'fixed' (with --rotor-speed and --pitch), a CSV with wind_speed, rotor_speed, pitch, or an "
                   "OpenFAST .fst whose ServoDyn (VSContrl 1, or 5 with a ROSCO DISCON.IN) gives the limits")
    p.add_argument("--tsr", choices=("optimal", "design"), default="optimal", help="region 2 of the rotor "
                   "schedule: at each draw's own C_P-maximizing tip-speed ratio (default) or the design one")
    p.add_argument("--rotor-speed", type=float, default=None, help="rotor speed [rpm] of --schedule fixed")
    p.add_argument("--pitch", type=float, default=None, help="pitch [deg] of --schedule fixed")
    p.add_argument("--weibull", default=None, help="a user wind distribution K,A (shape [-], scale [m/s])")
    p.add_argument("--histogram", default=None, metavar="CSV", help="a measured wind-speed histogram: columns "
                   "wind_speed [m/s] (bin centres) and hours or frequency; its AEP row headlines the report")
    p.add_argument("--availability", type=float, default=1.0, help="availability factor on the AEP (default 1)")
    p.add_argument("--measurement", action="append", default=[], metavar="NAME=KIND:PERCENT[:A|B]",
                   help="a stated measurement uncertainty (1-sigma), KIND wind, density or power, IEC 61400-12-1 "
                        "category B (default: correlated across bins) or A (uncorrelated); repeatable, "
                        "e.g. --measurement anemometer=wind:2 --measurement scatter=power:1:A")
    p.add_argument("--out", default=None, help="output folder (default RESULT_DIR/powercurve)")


def parse_wind(text: str) -> np.ndarray:
    """``START:STOP:STEP`` [m/s] as bin centres; an :class:`InputError` naming ``--wind`` otherwise."""
    parts = str(text).split(":")
    try:
        if len(parts) != 3:
            raise ValueError
        start, stop, step = (float(x) for x in parts)
    except ValueError:
        raise InputError(f"--wind {text!r}: expected START:STOP:STEP in m/s, e.g. 3:25:0.5", "--wind",
                         field="wind") from None
    return iec_bins(start, stop, step)


def _weibull(text):
    if text is None:
        return None
    try:
        k, A = (float(x) for x in str(text).split(","))
    except ValueError:
        raise InputError(f"--weibull {text!r}: expected K,A (shape, scale in m/s), e.g. 2,9.5", "--weibull",
                         field="weibull") from None
    weibull_cdf(1.0, k, A)          # refuses k <= 0, A <= 0 naming --weibull
    return k, A


def _schedule(args, model):
    s = args.schedule
    if s == "rotor":
        if model.rotor.schedule is None:
            raise InputError(f"the rotor {model.rotor.name!r} has no operating schedule: give --schedule fixed "
                             "--rotor-speed RPM --pitch DEG, or --schedule TABLE.csv", "--schedule", field="schedule")
        return VariableSpeed.from_rotor(model.rotor, args.tsr)
    if s == "fixed":
        if args.rotor_speed is None or args.pitch is None:
            raise InputError("--schedule fixed needs --rotor-speed RPM and --pitch DEG", "--schedule",
                             field="schedule")
        if not args.rotor_speed > 0:
            raise InputError(f"--rotor-speed must be > 0 rpm, got {args.rotor_speed!r}", "--rotor-speed",
                             field="rotor_speed")
        return FixedSpeed(args.rotor_speed, args.pitch)
    if s.lower().endswith(".fst"):
        from calib.powercurve.openfast_limits import schedule_from_openfast
        return schedule_from_openfast(s, float(model.rotor.rotor_radius), tsr_rule=args.tsr).schedule
    return schedule_from_table(s)


def distributions(weibull=None, histogram=None) -> dict:
    """The standard's Rayleigh table, an optional Weibull (k, A) and an optional measured histogram
    (:class:`calib.powercurve.histogram.WindHistogram`), as name -> cdf."""
    out = {f"Rayleigh {m:g} m/s": (lambda v, m=m: rayleigh_cdf(v, m)) for m in IEC_RAYLEIGH_MEANS}
    if weibull is not None:
        k, A = weibull
        out[f"Weibull k={k:g} A={A:g} m/s"] = lambda v: weibull_cdf(v, k, A)
    if histogram is not None:
        out[histogram.name()] = histogram.cdf
    return out


def run_powercurve(args, printer=print) -> int:
    from calib.calibration.result_files import load_result

    wind = parse_wind(args.wind)
    if not (np.isfinite(args.density) and args.density > 0):
        raise InputError(f"--density must be > 0 kg/m^3, got {args.density!r}", "--density", field="density")
    if args.draws < 0:
        raise InputError(f"--draws must be >= 0, got {args.draws}", "--draws", field="draws")
    if not 0 < args.availability <= 1:
        raise InputError(f"--availability must be in (0, 1], got {args.availability!r}", "--availability",
                         field="availability")
    weibull = _weibull(args.weibull)
    histogram = None
    if getattr(args, "histogram", None):
        from calib.powercurve.histogram import read_wind_histogram
        histogram = read_wind_histogram(args.histogram)
    items = [parse_measurement(m) for m in args.measurement]
    rdir = Path(args.result_dir)
    if not rdir.exists():
        raise InputError(f"no such result folder: {rdir}", "RESULT_DIR", field="result_dir")
    result = load_result(rdir)
    model = result.rebuild_model()
    from calib.powercurve.fmu import is_fmu_model
    if is_fmu_model(model) and args.schedule == "rotor" or is_fmu_model(model) and args.schedule.endswith(".fst"):
        raise InputError("an FMU result's power curve needs --schedule fixed (with --rotor-speed and --pitch) or "
                         "--schedule TABLE.csv", "--schedule", field="schedule")
    if not is_fmu_model(model) and (not hasattr(model, "solve") or not hasattr(model, "rotor")):
        raise InputError(f"calib powercurve needs a native-BEM or FMU result; this one's model is a "
                         f"{type(model).__name__}", str(rdir), field="model")
    schedule = _schedule(args, model)
    out = Path(args.out) if args.out else (rdir if rdir.is_dir() else rdir.parent) / "powercurve"
    pc = calibrated_power_curve(result, wind, schedule, args.density, args.draws, args.seed, items, model,
                                progress=lambda d, n: printer(f"[calib powercurve] draws {d}/{n}"))
    paths = write_outputs(pc, out, distributions(weibull, histogram), args.availability)
    printer(summary_paragraph(pc, pc.aep_table(distributions(weibull, histogram), args.availability)))
    printer(f"[calib powercurve] {pc.n_draws} draws in {pc.seconds:.1f} s ({pc.n_bem_points} BEM points); "
            f"wrote {', '.join(p.name for p in paths)} to {out}")
    return 0


# ---------------------------------------------------------------------------------------- words
def _headline(rows):
    for prefix in ("histogram", "Weibull"):
        for r in rows:
            if r["distribution"].startswith(prefix):
                return r
    return next((r for r in rows if r["distribution"] == "Rayleigh 8 m/s"), rows[0])


def summary_paragraph(pc: CalibratedPowerCurve, rows) -> str:
    """One plain paragraph from the numbers: the headline AEP, P90, the nominal model's, the
    calibration's share of the variance, the delta method against the draws, failures, extrapolation."""
    r = _headline(rows)
    sig = r["sigma_mwh"]
    by_draws = bool(np.isfinite(sig["calibration (draws)"]))
    cal = sig["calibration (draws)"] if by_draws else np.nan_to_num(r["sigma_calibration_delta_mwh"])
    total = r["sigma_total_mwh"]
    share = 100 * cal ** 2 / total ** 2 if total > 0 else float("nan")
    words = [f"Calibrated AEP at {r['distribution']}: {_energy(r['p50_mwh'])} (P90 {_energy(r['p90_mwh'])}, "
             f"1-σ {_energy(total)}); the nominal model said {_energy(r['nominal_aep_mwh'])}."]
    words.append(f"The calibration's share of the AEP variance is {share:.0f} % (1-σ {_energy(cal)} from "
                 f"{r['draws_used']} posterior draws, delta method {_energy(r['sigma_calibration_delta_mwh'])})"
                 if by_draws else f"The calibration's share of the AEP variance is {share:.0f} % (1-σ {_energy(cal)} "
                 "by the delta method only: no posterior draws)")
    others = [f"{k} {_energy(v)}" for k, v in sig.items() if k != "calibration (draws)" and v > 0]
    words[-1] += ("; the rest (1-σ) from " + ", ".join(others) + "." if others else "; no other source was stated.")
    sd, dd = pc.draw_std("power"), pc.delta_std.get("power")
    if dd is not None and np.any(np.isfinite(sd)):
        sig_ok = np.isfinite(sd) & (sd > 1e-3 * np.nanmax(np.abs(pc.central.power))) & np.isfinite(dd)
        ratio = dd[sig_ok] / sd[sig_ok]
        # the draws' σ scatters by 1/sqrt(2(N−1)): a bin is flagged beyond 10 % or twice that scatter
        scatter = 1 / np.sqrt(2 * max(pc.n_draws - 1, 1))
        limit = max(0.1, 2 * scatter)
        off = pc.wind_speed[sig_ok][np.abs(ratio - 1) > limit]
        if ratio.size:
            words.append(f"Per bin the delta method's σ of power is {np.min(ratio):.2f}–{np.max(ratio):.2f} × the "
                         f"draws' σ (which scatters by ±{100 * scatter:.0f} % with {pc.n_draws} draws)"
                         + (f", more than {100 * limit:.0f} % off at {_ranges(pc.wind_speed, np.isin(pc.wind_speed, off))} m/s."
                            if off.size else f", within {100 * limit:.0f} % in every bin with a spread."))
    words += [said for said in (delta_statement(pc, r), sampling_statement(r)) if said]
    if pc.simulations is not None:
        words.append(f"The FMU ran {pc.simulations} simulations for this power curve.")
    words.append(f"{pc.failed_draws} of {pc.n_draws} draws had a failed BEM solve in some bin "
                 f"({int(pc.failed_per_bin.sum())} bin solves); {int(np.count_nonzero(~pc.central.ok))} central bins "
                 f"failed; {pc.n_clipped} draws were clipped to a parameter bound.")
    words += [f"Warning: {w}." for w in pc.warnings]
    words += [f"{n[0].upper()}{n[1:]}." for n in pc.notes if "has no posterior" in n or n.startswith("left out")]
    outside = np.array([bool(e) for e in pc.envelope])
    if outside.any():
        words.append(f"{int(outside.sum())} bins lie outside the calibration envelope (extrapolation): "
                     f"{_ranges(pc.wind_speed, outside)} m/s, e.g. {next(e for e in pc.envelope if e)}.")
    return " ".join(words)


def _energy(mwh: float) -> str:
    """An energy in MWh as "18.62 GWh", "341 MWh" or "0.53 MWh" (three or four significant figures)."""
    if not np.isfinite(mwh):
        return "n/a"
    return f"{mwh / 1e3:.4g} GWh" if abs(mwh) >= 1e3 else f"{mwh:.3g} MWh"


def _ranges(v, mask) -> str:
    """The runs of ``v`` where ``mask`` holds, as "3–5.5, 14.5–25"."""
    runs, start = [], None
    for k in range(len(v) + 1):
        on = k < len(v) and mask[k]
        if on and start is None:
            start = k
        elif not on and start is not None:
            runs.append(f"{v[start]:g}" if start == k - 1 else f"{v[start]:g}–{v[k - 1]:g}")
            start = None
    return ", ".join(runs)


# ---------------------------------------------------------------------------------------- tables
def bin_rows(pc: CalibratedPowerCurve) -> list[dict]:
    eta = pc.generator_efficiency
    c, n = pc.central, pc.nominal
    meas = pc.measurement_std()
    total = pc.power_std_total()
    q05, q95 = pc.draw_quantile("power", 0.05), pc.draw_quantile("power", 0.95)
    rows = []
    for k, v in enumerate(pc.wind_speed):
        row = {"wind_speed [m/s]": v, "rotor_speed [rpm]": c.rotor_speed[k], "pitch [deg]": c.pitch[k],
               "power_aero [W]": c.power[k], "power_electrical [W]": eta * c.power[k], "cp [-]": c.cp[k],
               "ct [-]": c.ct[k], "thrust [N]": c.thrust[k], "region": int(c.region[k]),
               "nominal_power_aero [W]": n.power[k], "nominal_cp [-]": n.cp[k],
               "nominal_thrust [N]": n.thrust[k]}
        for q, u in (("power", "W"), ("thrust", "N"), ("cp", "-"), ("ct", "-"), ("rotor_speed", "rpm"),
                     ("pitch", "deg")):
            row[f"{q}_std_draws [{u}]"] = pc.draw_std(q)[k]
        for q, u in (("power", "W"), ("thrust", "N"), ("pitch", "deg")):
            row[f"{q}_std_delta [{u}]"] = pc.delta_std[q][k] if q in pc.delta_std else float("nan")
        row["power_q05_draws [W]"], row["power_q95_draws [W]"] = q05[k], q95[k]
        row["power_std_discrepancy [W]"] = pc.discrepancy_std[k]
        row["power_std_field [W]"] = pc.field_std[k]
        for name, u in meas.items():
            row[f"power_electrical_std_{name} [W]"] = u[k]
        row["power_electrical_std_total [W]"] = total[k]
        row["draws_failed"] = int(pc.failed_per_bin[k])
        row["status"] = int(c.status[k])
        row["envelope"] = pc.envelope[k] or "inside"
        rows.append(row)
    return rows


def _csv_text(rows, comment) -> str:
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow([f"# {comment}"])
    w.writerow(list(rows[0]))
    for r in rows:
        w.writerow([f"{x:.8g}" if isinstance(x, float) else x for x in r.values()])
    return buf.getvalue()


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return float(x) if np.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _meta(pc: CalibratedPowerCurve) -> dict:
    return {"schedule": pc.schedule.describe(), "air_density_kg_m3": pc.air_density, "draws": pc.n_draws,
            "draws_failed": pc.failed_draws, "draws_clipped_to_bounds": pc.n_clipped,
            "draws_seconds": pc.seconds, "bem_points": pc.n_bem_points,
            "generator_efficiency": pc.generator_efficiency,
            "measurements": [m.words() for m in pc.measurements], "notes": pc.notes,
            "format": "calib power curve 1: IEC 61400-12-1 bins; no open exchange format followed"}


def write_outputs(pc: CalibratedPowerCurve, out, cdfs: dict, availability: float = 1.0) -> list[Path]:
    """Tables, figures and report.md into ``out``; returns the paths written."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = bin_rows(pc)
    aep_rows = pc.aep_table(cdfs, availability)
    paths = [atomic_write_text(out / "powercurve.csv", _csv_text(rows, pc.schedule.describe())),
             atomic_write_text(out / "powercurve.json", json.dumps(_jsonable({**_meta(pc), "bins": rows}), indent=1))]
    flat = []
    for r in aep_rows:
        f = {k: v for k, v in r.items() if not isinstance(v, dict) and v is not None}
        f.update({f"sigma_{k}_mwh": v for k, v in r["sigma_mwh"].items()})
        f.update({f"sigma_measurement_category_{k}_mwh": v for k, v in r["sigma_measurement_mwh"].items()})
        split = r.get("sigma_calibration_split_mwh") or {}
        f.update({f"sigma_calibration_delta_{k}_directions_mwh": v for k, v in split.items()})
        eb = (r.get("empirical_bayes") or {}).get("tau")
        if eb:
            f.update({"empirical_bayes_amplitude": eb["amplitude"], "empirical_bayes_sigma_total_mwh":
                      eb["sigma_total_mwh"], "empirical_bayes_p90_mwh": eb["p90_mwh"]})
        flat.append(f)
    paths.append(atomic_write_text(out / "aep.csv", _csv_text(flat, "AEP [MWh], IEC 61400-12-1 formula")))
    paths.append(atomic_write_text(out / "aep.json", json.dumps(_jsonable({**_meta(pc), "aep": aep_rows}), indent=1)))
    from calib.powercurve.figures import aep_figure, cp_tsr_figure, power_curve_figure
    for name, fig in (("powercurve.png", power_curve_figure(pc)), ("cp_tsr.png", cp_tsr_figure(pc)),
                      ("aep.png", aep_figure(aep_rows))):
        with atomic_path(out / name) as tmp:
            with open(tmp, "wb") as fh:
                fig.savefig(fh, format="png", dpi=110)
        paths.append(out / name)
    paths.append(atomic_write_text(out / "report.md", report_text(pc, aep_rows)))
    return paths


def report_text(pc: CalibratedPowerCurve, aep_rows) -> str:
    lines = ["# Power curve and AEP of the calibrated model", "", summary_paragraph(pc, aep_rows), "",
             f"Schedule: {pc.schedule.describe()}. Air density {pc.air_density:g} kg/m³; generator efficiency "
             f"{pc.generator_efficiency:g} (AEP on electrical power).", ""]
    lines += [f"- {n}" for n in pc.notes]
    lines += ["", "![power curve](powercurve.png)", "", "![C_P(λ)](cp_tsr.png)", "", "![AEP](aep.png)", "",
              "| distribution | P50 [MWh] | P90 [MWh] | nominal [MWh] | σ total | σ calibration (draws) | σ delta |",
              "|---|---|---|---|---|---|---|"]
    for r in aep_rows:
        lines.append(f"| {r['distribution']} | {r['p50_mwh']:.4g} | {r['p90_mwh']:.4g} | {r['nominal_aep_mwh']:.4g} | "
                     f"{r['sigma_total_mwh']:.3g} | {r['sigma_mwh']['calibration (draws)']:.3g} | "
                     f"{r['sigma_calibration_delta_mwh']:.3g} |")
    lines += _measurement_table(pc, aep_rows) + _statistic_lines(aep_rows)
    return "\n".join(lines) + "\n"


def _measurement_table(pc: CalibratedPowerCurve, aep_rows) -> list[str]:
    """The stated measurement items as IEC 61400-12-1 tabulates them, with their AEP 1-σ at the headline
    distribution (category B added linearly over the bins, category A in quadrature; Annex E)."""
    if not pc.measurements:
        return ["", "No measurement uncertainty items were stated (``--measurement NAME=KIND:PERCENT[:A|B]``)."]
    r = _headline(aep_rows)
    how = {"A": "uncorrelated across bins (quadrature)", "B": "correlated across bins (linear)"}
    lines = ["", f"Measurement uncertainty items (IEC 61400-12-1 categories; AEP at {r['distribution']}):", "",
             "| item | category | quantity | stated 1-σ | over the bins | σ AEP [MWh] |", "|---|---|---|---|---|---|"]
    for m in pc.measurements:
        lines.append(f"| {m.name} | {m.category} | {m.kind} | {100 * m.relative:g} % | {how[m.category]} "
                     f"| {r['sigma_mwh'][m.name]:.3g} |")
    t = r["sigma_measurement_mwh"]
    lines += [f"| category A combined | A | | | quadrature | {t['A']:.3g} |",
              f"| category B combined | B | | | quadrature of the items | {t['B']:.3g} |",
              f"| measurement total | A + B | | | quadrature | {t['total']:.3g} |"]
    return lines


def _statistic_lines(aep_rows) -> list[str]:
    """Where the calibration's AEP variance comes from (data-determined or prior-dominated directions) and the
    empirical-Bayes alternative (:func:`calib.powercurve.field.prior_split`), at the headline distribution."""
    r = _headline(aep_rows)
    split, eb = r.get("sigma_calibration_split_mwh"), (r.get("empirical_bayes") or {})
    if not split:
        return []
    out = ["", f"At {r['distribution']}, the calibration's nodal 1-σ (delta method) is {_energy(split['data'])} "
           f"along the directions the data determine and {_energy(split['prior'])} along those the prior dominates; "
           f"the field between the nodes adds {_energy(r['sigma_mwh']['field between nodes'])}."]
    if "tau" in eb:
        t = eb["tau"]
        rng = "".join(f", {_energy(eb[k]['sigma_total_mwh'])} at its interval's {w} end τ = {eb[k]['amplitude']:.2g}"
                      for k, w in (("tau_lower", "lower"), ("tau_upper", "upper")) if k in eb)
        out[-1] += (f" With the field's prior amplitude at the prior check's τ̂ = {t['amplitude']:.2g} instead of the "
                    f"stated 1 (empirical Bayes, the estimate kept), the total 1-σ would be "
                    f"{_energy(t['sigma_total_mwh'])} instead of {_energy(r['sigma_total_mwh'])} (P90 "
                    f"{_energy(t['p90_mwh'])}){rng}.")
    return out
