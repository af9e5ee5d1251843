"""MkDocs hook: tables generated at build time, so that they cannot drift.

- ``<!-- settings: module.Class section -->`` becomes the table of that settings dataclass's fields,
  defaults and documented meaning (:func:`calib.report.settings_doc.settings_markdown`);
- ``<!-- bench: NAME -->`` becomes the tables of the benchmark output ``docs/validation/data/NAME.json``,
  which the benchmark writes with its date, commit and command: through a renderer of :data:`RENDERERS`,
  or, for the others, the tables the benchmark wrote into the file's ``markdown``.
"""

import importlib
import itertools
import re

MARKER = re.compile(r"^<!-- settings: ([\w.]+)\.(\w+) (\w+) -->$", re.M)


#: A Sphinx role left in a rendered docstring (mkdocstrings does not read them): ":class:<code>~a.b.C</code>".
ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|obj|exc|ref):<code>(~?)([^<]+)</code>")


def on_page_content(html, page, config, files):
    """The docstrings' Sphinx roles as code: ``:class:`~calib.history.RecordedModel``` reads
    ``RecordedModel`` (the tilde: the last name only), ``:func:`calib.x.f``` reads ``calib.x.f``."""
    return ROLE.sub(lambda m: f"<code>{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}</code>", html)


def on_page_markdown(markdown, page, config, files):
    from calib.report.settings_doc import settings_markdown

    def table(m):
        cls = getattr(importlib.import_module(m.group(1)), m.group(2))
        return settings_markdown(cls, m.group(3))

    return _bench(MARKER.sub(table, markdown), config)


BENCH = re.compile(r"^<!-- bench: (\w+) -->$", re.M)


def _stamp(data: dict) -> str:
    """The commit a run started on, and the one it published at when HEAD moved during the run."""
    moved = data.get("commit_at_publish")
    return f"`{data['commit']}`" + (f" (published at `{moved}`)" if moved else "")


def _prediction_tables(data: dict) -> str:
    """The extrapolation benchmark's tables (benchmarks/bench_prediction.py)."""
    out = [f"*From `{data['command']}`, {data['date']}, commit {_stamp(data)}"
           + (f"; {data['note']}" if data.get("note") else "") + ".*", "",
           "| family (splits) | MAP: calibrated ≤ nominal | within 2√(2/N) | inside 95 % | "
           "truncated: ≤ nominal | within | inside |", "|---|---|---|---|---|---|---|"]
    labels = {"out_of_family": "CCBlade, out of family", "phase_vi": "Phase VI, measured",
              "prior_draws": "twin (d), prior draws", "all": "all"}
    for key, label in labels.items():
        m, t = data["summary"]["map"][key], data["summary"]["truncated"][key]
        out.append(f"| {label} ({m['splits']}) | {m['better_than_nominal']} | {m['not_worse_beyond_scatter']} | "
                   f"{100 * m['coverage_95']:.1f} % | {t['better_than_nominal']} | {t['not_worse_beyond_scatter']} | "
                   f"{100 * t['coverage_95']:.1f} % |")
    failed = sum(data["summary"][e]["all"]["failed_points"] for e in ("map", "truncated"))
    rules = {"stated": "stated prior (1)", "estimate": "τ̂", "bound": "upper bound (calib)"}
    if "field_rules" in data["summary"]["map"]["all"]:
        out += ["", "The MAP's field between and beyond the nodes carried at three amplitudes: inside the 95 % "
                "intervals and χ²/N with the prediction variance:", "",
                "| family | " + " | ".join(rules.values()) + " |", "|---" * (len(rules) + 1) + "|"]
        for key, label in labels.items():
            fr = data["summary"]["map"][key]["field_rules"]
            out.append(f"| {label} | " + " | ".join(
                f"{100 * fr[r]['coverage_95']:.1f} %, {fr[r]['chi2_per_n_predictive']:.2f}" for r in rules) + " |")
    if "worse_than_nominal_rows" in data["summary"]["map"]["all"]:
        out += ["", "Where the calibrated model predicts worse than the nominal one (χ²/N, noise only), the "
                "held-back points whose 95 % half-width is at least the nominal model's error there: " + "; ".join(
                    f"{est} {data['summary'][est]['all']['worse_than_nominal_wider']} of "
                    f"{data['summary'][est]['all']['worse_than_nominal_rows']}" for est in ("map", "truncated")) + "."]
    out += ["", f"Held-back points that failed to evaluate: {failed}.", "",
            "Held-back χ²/N (noise only), calibrated / nominal, per CCBlade data set:", "",
            "| data set | MAP, low → high | MAP, high → low | truncated, low → high | truncated, high → low |",
            "|---|---|---|---|---|"]
    for name in data["out_of_family"]["map"]:
        cells = []
        for est in ("map", "truncated"):
            case = data["out_of_family"][est][name]
            for direction in ("low to high", "high to low"):
                c = case[direction]
                cells.append(f"{c['chi2_per_n_calibrated']:.3g} / {c['chi2_per_n_nominal']:.3g}")
        out.append(f"| {name.replace('_', ' ')} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


def _coverage_tables(load) -> str:
    """The coverage twins (c) and (d), both estimators (benchmarks/bench_coverage.py)."""
    runs = {e: load(f"coverage_{e}") for e in ("map", "truncated")}
    cols = [(t, e) for t in ("c_prior_draws", "d_prior_draws_outside_span") for e in ("map", "truncated")]
    out = [f"*{e}: from `{r['command']}`, {r['date']}, commit {_stamp(r)}, {r['n_seeds']} seeds.*"
           for e, r in runs.items()]
    out += ["", "| | " + " | ".join(f"({t[0]}) {e}" for t, e in cols) + " |", "|---" * (len(cols) + 1) + "|"]

    def row(label, fmt):
        cells = []
        for t, e in cols:
            v = runs[e]["twins"].get(t, {})
            try:
                cells.append(fmt(v))
            except (KeyError, TypeError):
                cells.append("not measured")
        out.append(f"| {label} | " + " | ".join(cells) + " |")

    row("95 % band coverage, ΔC_L / ΔC_D", lambda v: f"{100 * v['coverage_lift_mean']:.1f} % / "
                                                     f"{100 * v['coverage_drag_mean']:.1f} %")
    row("NEES of the whole vector (its 95 % band)", lambda v: f"{v['nees_full_vector_sum']:.0f} "
        f"({v['nees_full_vector_band'][0]:.0f}–{v['nees_full_vector_band'][1]:.0f})")
    row("in-sample predictive χ² per row", lambda v: f"{v['in_sample_predictive_chi2_per_row']:.2f}")
    row("in-sample predictive χ² per degree of freedom", lambda v: f"{v['in_sample_predictive_chi2_per_dof']:.2f}")
    row("rows inside the 95 % predictive interval", lambda v: f"{100 * v['in_sample_predictive_coverage_95']:.1f} %")
    row("calibrations not converged / not stable", lambda v: f"{v['not_converged']}")
    row("seconds per calibration", lambda v: f"{v['seconds_per_calibration']:.1f}")
    return "\n".join(out) + "\n"


def _speed_tables(data: dict) -> str:
    """``make bench``'s figures (benchmarks/run_all.py, speed suite)."""
    m = data["machine"]
    out = [f"*From `{data['command']}`, {data['date']}, commit {_stamp(data)}, on {m['cpu_count']} cores "
           f"({m['platform']}, Python {m['python']}); ratios are measured within the one run.*", "",
           "| benchmark | ratio | detail | target |", "|---|---|---|---|"]
    for r in data["ratios"]:
        if r.get("value") is None:
            continue
        cells = [r["name"], f"{r['value']:.3g}", r["detail"], r.get("target", "")]
        out.append("| " + " | ".join(str(c).replace("|", "\\|") for c in cells) + " |")
    cal = data.get("calibration", {})
    if cal:
        out += ["", f"Paper-size calibration ({cal.get('calibration_params')} parameters, "
                    f"{cal.get('calibration_points')} points, 4 channels, native BEM): MAP "
                    f"{cal['calibration_map_seconds']:.2f} s ({cal.get('calibration_map_model_jacobians')} Jacobians; "
                    f"target ≤ 0.2 s), truncated at σ̄ 0.5 {cal['calibration_seconds']:.2f} s."]
    sc = data.get("scaling", {})
    if sc:
        out += ["", "Cost against the campaign's size (the wind-tunnel study on denser grids, `bench_scaling.py`; "
                    "target: 2592 points in ≤ 10 s with the MAP):", "",
                "| estimator | points | seconds | ms per point | model Jacobians | status |", "|---|---|---|---|---|---|"]
        for key, r in sc.items():
            out.append(f"| {key.split('_')[0]} | {r['points']} | {r['seconds']:.1f} | {r['ms_per_point']:.1f} | "
                       f"{r['model_jacobians']} | {r['status']} |")
    cc = data.get("ccblade", {})
    if "smoothed_native_max_abs_dcp" in cc:
        out += ["", f"With the native polars smoothed as CCBlade's CCAirfoil spline smooths them, the two C_P "
                    f"surfaces agree to max |ΔC_P| {cc['smoothed_native_max_abs_dcp']:.2g} (median "
                    f"{cc['smoothed_native_median_abs_dcp']:.2g})."]
    fmu = data.get("fmu", {})
    if fmu:
        out += ["", "Turbine FMUs (NREL 5-MW, all effects on): " + ", ".join(
            f"variant {k.split('_')[1]} {v:.0f}× real time" for k, v in sorted(fmu.items())) + "."]
    return "\n".join(out) + "\n"


#: NAME of ``<!-- bench: NAME -->`` -> renderer of the published files (``load(name)`` reads one)
RENDERERS = {"prediction": lambda load: _prediction_tables(load("prediction")),
             "speed": lambda load: _speed_tables(load("speed")),
             "coverage": _coverage_tables}
#: The data files a marker's table is made from, where they are not the one named by the marker.
SOURCES = {"coverage": ("coverage_map", "coverage_truncated")}


#: Published tables too wide for the content column, split by columns into narrower ones: NAME of the
#: benchmark -> the column groups by header, each with the columns that name a row. Every column of
#: the table is in a group, so that every number still reaches the page.
BATTERY_COLUMNS = (("set-up", "data set", "right / total", "alone", "χ²/dof before (median)", "s / diagnosis"),
                   ("set-up", "data set", "counts as right", "first verdicts", "all named"))
SPLITS = {"diagnosis_out_of_family": BATTERY_COLUMNS, "diagnosis_out_of_method": BATTERY_COLUMNS}

#: A cell boundary of a Markdown table row (a ``|`` not escaped as ``\|``).
CELL = re.compile(r"(?<!\\)\|")


def _cells(line: str) -> list[str]:
    """The cells of one Markdown table row, stripped."""
    return [c.strip() for c in CELL.split(line.strip())[1:-1]]


def _split_tables(markdown: str, groups: tuple, name: str) -> str:
    """``markdown`` with the table whose columns are those of ``groups`` written as one table per group.

    Raises
    ------
    ValueError
        When no table has exactly those columns: the benchmark's table changed, and ``SPLITS[name]``
        must follow it (a column left out would drop its numbers from the page).
    """
    if not groups:
        return markdown
    wanted = {c for group in groups for c in group}
    out, done = [], False
    for is_table, block in itertools.groupby(markdown.split("\n"), key=lambda line: line.startswith("|")):
        block = list(block)
        header = _cells(block[0]) if is_table else []
        if sorted(header) != sorted(wanted):
            out += block
            continue
        rows = [_cells(line) for line in block[2:]]
        for j, group in enumerate(groups):
            at = [header.index(c) for c in group]
            out += ([""] if j else []) + ["| " + " | ".join(group) + " |", "|---" * len(group) + "|"]
            out += ["| " + " | ".join(row[i] for i in at) + " |" for row in rows]
        done = True
    if not done:
        raise ValueError(f"docs/hooks.py SPLITS[{name!r}]: no table of docs/validation/data/{name}.json has the "
                         f"columns {sorted(wanted)}; update SPLITS to the benchmark's table")
    return "\n".join(out)


def _published_markdown(data: dict, name: str) -> str:
    """A benchmark's own tables (``publish(..., markdown=...)``) under its run's date, commit and command,
    the wide ones split by :data:`SPLITS`."""
    body = re.sub(r"^## ", "### ", data["markdown"].strip(), flags=re.M)    # the page owns the sections
    body = _split_tables(body, SPLITS.get(name, ()), name)
    return f"*From `{data['command']}`, {data['date']}, commit {_stamp(data)}.*\n\n" + body + "\n"


def _bench(markdown: str, config) -> str:
    import json
    from pathlib import Path

    def load(name):
        return json.loads((Path(config["docs_dir"]) / "validation" / "data" / f"{name}.json").read_text())

    def render(m):
        name = m.group(1)
        missing = [f for f in SOURCES.get(name, (name,))
                   if not (Path(config["docs_dir"]) / "validation" / "data" / f"{f}.json").is_file()]
        if missing:
            return (f"*Not published yet: no run of the benchmark that writes "
                    f"{', '.join(f'`docs/validation/data/{f}.json`' for f in missing)} is on record in this version.*\n")
        if name in RENDERERS:
            return RENDERERS[name](load)
        return _published_markdown(load(name), name)

    return BENCH.sub(render, markdown)
