"""A self-contained HTML report (images embedded as base64 PNG) of one or more calibrations.

The report is written to a temporary name in its folder and renamed
(:mod:`calib.report.atomic`), so an interrupted run never leaves a truncated ``report.html``.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Mapping

import numpy as np

from calib.calibration.result import CalibrationResult
from calib.report.atomic import atomic_write_text
from calib.report.result_sentences import sentences
from calib.words import p_text

_MIME = {"png": "image/png", "svg": "image/svg+xml"}

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222;line-height:1.4}
.table{overflow-x:auto;max-width:100%;margin:0.5em 0 1.2em}table{border-collapse:collapse}
td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}img{max-width:100%;height:auto;margin:0.4em 0}
tr.above td{border-bottom-style:hidden}tr.detail td{text-align:left;font-size:.9em;color:#555;padding-left:1.6em}
pre{white-space:pre-wrap;overflow-wrap:anywhere}
.bad{color:#b00}.ok{color:#070}h2{border-bottom:2px solid #ddd;padding-bottom:2px}
"""
# Layout at any window width: cells wrap at spaces only (a name never breaks inside), long text
# goes on a detail line under its row; a table still too wide scrolls inside its own box (.table),
# never the page; preformatted text wraps. tests/test_browser_report.py fails when a table needs
# its scroll box at 1100 px or a name breaks.


def _img(path: Path) -> str:
    path = Path(path)
    mime = _MIME.get(path.suffix.lstrip(".").lower(), "image/png")
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(path.stem)}" src="data:{mime};base64,{data}">'


def _figure_html(name: str, paths: Mapping[str, Path], caption: str = "") -> str:
    """A figure heading, an optional caption and the embedded image (PNG, else SVG); empty if neither."""
    fmt = next((f for f in ("png", "svg") if f in paths), None)
    if fmt is None:
        return ""
    cap = f"<p>{html.escape(caption)}</p>" if caption else ""
    return f"<h4>{html.escape(name.replace('_', ' '))}</h4>{cap}" + _img(paths[fmt])


def _captions(r: CalibrationResult) -> dict[str, str]:
    """Captions of the standard figures, generated from the result."""
    from calib.report.fit_figures import fit_abscissa

    _, xlabel, reason = fit_abscissa(r)
    grouping = "Correction nodes grouped by block and α node; other parameters by name." if _has_field(r) else \
        "Parameters by name."
    if r.estimator == "map":
        every = (f"The {r.n_retained} directions the data determine better than the prior are drawn, on the α and "
                 f"η range of the correction nodes.")
        spectrum = (f"Singular values of the prior-whitened sensitivities: {r.n_retained} of {r.n_params} directions "
                    f"above 1, where the data determine the field better than the prior; the estimate moves every "
                    f"direction, each as far as the data outweigh the prior.")
    else:
        every = f"All {r.n_retained} retained eigenshapes are drawn, on the α and η range of the correction nodes."
        spectrum = f"{r.n_retained} of {r.n_params} directions retained."
    return {"singular_values": spectrum,
            "eigenshapes_lift": every, "eigenshapes_drag": every,
            "fit": f"Against {xlabel.split(' [')[0]} ({reason}); under each channel the whitened residual after "
                   f"calibration.",
            "correlation": grouping}


def _has_field(r: CalibrationResult) -> bool:
    """Whether the calibrated model has a correction field (an FMU may offer scalar parameters only)."""
    return any(v["kind"] in ("lift_correction", "drag_correction") for v in r.identifiability.verdicts)


def _table(header, rows, left=1, details=()) -> str:
    """An HTML table in its scroll box: the first ``left`` columns left-aligned, the others right-aligned.

    ``details`` (HTML, one per row, "" for none) go on a line under their row, across the table:
    long text that would widen a column of short numbers.
    """
    th = "".join(f'<th class="{"l" if i < left else ""}">{html.escape(str(h))}</th>' for i, h in enumerate(header))
    body = ""
    for row, detail in zip(rows, list(details) or [""] * len(rows)):
        cells = "".join(f'<td class="{"l" if i < left else ""}">{c}</td>' for i, c in enumerate(row))
        body += (f'<tr class="above">{cells}</tr><tr class="detail"><td colspan="{len(header)}">{detail}</td></tr>'
                 if detail else f"<tr>{cells}</tr>")
    return f'<div class="table"><table><tr>{th}</tr>{body}</table></div>'


def _fmt(x, digits=4) -> str:
    if isinstance(x, (float, np.floating)):
        return f"{x:.{digits}g}"
    return html.escape(str(x))


def _directions_words(estimator: str) -> str:
    """One plain sentence on what the key table's directions (or θ and σ̄) mean for the user."""
    if estimator == "map":
        return ("A direction is one statistically independent combination of the parameters (from the SVD of "
                "the prior-whitened sensitivities); s > 1 means the measurements pin it down better than the "
                "prior did, the others stay close to the prior.")
    return ("θ are the statistically independent combinations of the parameters (from the SVD of the Fisher "
            "information); the retained θ are those the measurements determine with confidence, the others stay "
            "at nominal. σ̄ is the largest standard deviation a retained θ may have, in units of the parameters' "
            "scales.")


def result_section(result: CalibrationResult, figures: Mapping[str, Mapping[str, Path]] | None = None,
                   checks: Mapping[str, str] | None = None) -> str:
    """HTML of one calibration: statements, key numbers, verdicts, fit, failures, figures.

    ``checks`` adds named statements (e.g. coverage of a known truth in a synthetic run).
    """
    r = result
    gof = r.goodness_of_fit()
    status_cls = "ok" if r.estimate.status == "converged" else "bad"
    parts = [f"<h2>{html.escape(r.name)}</h2>",
             f'<p>Status: <b class="{status_cls}">{html.escape(r.estimate.status)}</b> — '
             f'{html.escape(r.estimate.message)}. '
             f"Wall time {r.provenance.wall_time:.2f} s.</p>"]
    parts.append("<ul>" + "".join(f"<li>{html.escape(t)}</li>" for t in sentences(r)) + "".join(
        f"<li><b>{html.escape(k)}</b>: {html.escape(v)}</li>" for k, v in (checks or {}).items()) + "</ul>")
    parts += _key_numbers_html(r, gof)
    parts.append(_failures_html(r))
    parts += _fit_tables_html(r, gof)
    parts.append(_verdicts_html(r))
    if figures:
        parts.append("<h3>Figures</h3>")
        captions = _captions(r)
        for name, paths in figures.items():
            parts.append(_figure_html(name, paths, captions.get(name, "")))
    parts.append("<details><summary>Reproducibility</summary><pre>" + html.escape(
        "\n".join([f"inputs: {r.provenance.inputs}", f"versions: {r.provenance.versions}",
                   f"settings: { {k: v for k, v in r.provenance.settings.items() if k != 'lower_effective'} }"])) +
        "</pre></details>")
    return "\n".join(parts)


def _key_numbers_html(r: CalibrationResult, gof: dict) -> list[str]:
    """The key-number table (estimator, directions, χ² before and after, settings, verdict counts)
    and the paragraph that explains it; ``gof`` is the result's goodness of fit."""
    ident = r.identifiability
    if r.estimator == "map":
        how = [("estimator", "MAP under the stated prior"),
               ("directions the data determine better than the prior (s > 1)", r.n_retained)]
    else:
        how = [("estimator", "truncated ML"), ("retained θ", r.n_retained),
               ("truncation", f"{ident.truncation.get('criterion', 'K-fold')} cross-validation" if ident.truncation
                else "threshold σ̄"), ("σ̄ [scale units]", ident.sigma_bar)]
    key = [("operating points", r.n_points), ("channels", ", ".join(r.channels)), ("parameters", r.n_params)] + how
    key += [("χ²/dof before (dof = N)", gof["chi2_per_dof_before"]), ("N", gof["dof_before"]),
            ("χ²/dof after (dof = N − fitted directions)", gof["chi2_per_dof_after"]), ("dof after", gof["dof_after"]),
            ("p-value after", p_text(gof["p_value_after"])),
            ("optimizer", r.provenance.settings.get("optimizer")), ("noise", r.provenance.settings.get("noise")),
            ("prior σ of correction nodes [scale units]" if _has_field(r) else "prior σ [scale units]",
             r.provenance.settings.get("prior_sigma"))]
    key += [(f"verdict: {k}", v) for k, v in r.verdict_counts().items()]
    return [_table(["quantity", "value"], [(html.escape(k), _fmt(v)) for k, v in key]),
            "<p class='explain'>" + html.escape(_directions_words(r.estimator)) +
            " χ²/dof is the mean squared misfit in units of the noise: near 1 the model "
            "explains the measurements to within their noise, far above 1 it misses them. The p-value is the "
            "chance of a misfit at least this large if the model were right and the noise as stated.</p>"]


def _failures_html(r: CalibrationResult) -> str:
    """The failed model points of the run, in red when any remain."""
    fail = r.fit.failures
    fail_cls = "bad" if fail.get("final", 0) or fail.get("total_failed_point_evaluations", 0) else "ok"
    return (f'<p class="{fail_cls}">Failed model points: nominal {fail.get("nominal", 0)}, final '
            f'{fail.get("final", 0)}, over all evaluations {fail.get("total_failed_point_evaluations", 0)} '
            f'({fail.get("model_evaluations", 0)} evaluations, {fail.get("model_jacobians", 0)} '
            f"Jacobians).</p>")


def _fit_tables_html(r: CalibrationResult, gof: dict) -> list[str]:
    """The fit per channel and the worst points after calibration; ``gof`` is the result's goodness of fit."""
    per_channel = "<h3>Fit per channel</h3>" + _table(
        ["channel", "unit", "noise σ [unit]", "χ²/point before [-]", "χ²/point after [-]", "RMS misfit before [unit]",
         "RMS misfit after [unit]"],
        [(html.escape(c), html.escape(u), _fmt(float(s)), _fmt(gof["per_channel"][c]["chi2_per_point_before"]),
          _fmt(gof["per_channel"][c]["chi2_per_point_after"]), _fmt(gof["per_channel"][c]["rms_before"]),
          _fmt(gof["per_channel"][c]["rms_after"]))
         for c, u, s in zip(r.channels, r.channel_units, r.fit.noise_sigma)])
    worst = "<h3>Worst points after calibration</h3>" + _table(
        ["point", "channel", "whitened residual [σ]", "conditions"],
        [(w["point"], html.escape(w["channel"]), _fmt(w["whitened_residual"], 3),
          html.escape(", ".join(f"{k} {v:.4g}" for k, v in w["conditions"].items())))
         for w in gof["worst"]])
    return [per_channel, worst]


def _verdicts_html(r: CalibrationResult) -> str:
    """The verdict table (every parameter but the poorly observable nodes within 2σ of nominal) and
    what the verdicts mean."""
    rows, details = [], []
    for v in r.identifiability.verdicts:
        if v["kind"] in ("lift_correction", "drag_correction") and v["verdict"] == "poorly observable" \
                and not v["note"]:
            continue
        rows.append((html.escape(v["name"]), html.escape(v["verdict"]), html.escape(v.get("unit", "") or "-"),
                     _fmt(v["nominal"]), _fmt(v["value"]),
                     _fmt(v["std"]), _fmt(v["prior_std"]), _fmt(v["std_ratio"], 2), html.escape(v.get("note", ""))))
        details.append(html.escape(_shared_words(v)))
    n_hidden = len(r.identifiability.verdicts) - len(rows)
    which = (f"Every non-field parameter, and every correction node that is identified, at a bound, or moved more "
             f"than 2σ; {n_hidden} poorly observable nodes within 2σ of nominal are not listed (their bands are as "
             f"wide as the prior)." if _has_field(r) else "Every parameter of the model.")
    return (f"<h3>Verdicts</h3><p>{which}</p>" +
            _table(["parameter", "verdict", "unit", "nominal", "estimate", "σ (1σ)", "prior σ", "σ/prior", "note"],
                   rows, left=3, details=details) +
            "<p class='explain'>σ is the standard deviation of the estimate (1σ); σ/prior compares it with "
            "the prior's: <b>identified</b> when the data halve it at least, <b>poorly observable</b> when "
            "the band stays close to the prior's width, <b>at bound</b> when the estimate sits on a bound "
            "(its value is the bound, not an estimate), <b>confounded</b> when a nuisance shares most of "
            "its information with the correction field (read it with its σ, not as a measurement of that "
            "quantity alone).</p>")


def _shared_words(v: dict) -> str:
    """Whom a parameter shares its information with, for the line under its verdict ("" for a
    correction node, or a result saved before the shared information)."""
    if not v.get("confounded_with"):
        return ""
    share = (f"{100 * v['shared_information']:.0f} % of its information with the other parameters, most"
             if "shared_information" in v else "its information most")
    return f"{v['name']} shares {share} with {v['confounded_with']}"


def decision_html(r: CalibrationResult) -> str:
    """One paragraph an engineer reads first: how the calibration ended, the misfit before and
    after, what the data determined, and every warning the run raised."""
    gof = r.goodness_of_fit()
    counts = r.verdict_counts()
    ended = "ended converged" if r.estimate.status == "converged" else f"did NOT converge (status {r.estimate.status})"
    fit = ("consistent with the noise" if gof["p_value_after"] > 0.01 else "worse than the stated noise explains")
    verdicts = ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in counts.items() if v)
    warnings = [t for t in [r.estimate.message, *r.provenance.checks.values()] if "WARNING" in t]
    text = (f"{r.name}: the calibration {ended}; χ²/dof {gof['chi2_per_dof_before']:.3g} before → "
            f"{gof['chi2_per_dof_after']:.3g} after against {r.noise_words()}, {fit}; of {r.n_params} parameters: "
            f"{verdicts}.")
    failed = r.fit.failures.get("final", 0)
    if failed:
        text += f" {failed} operating point(s) failed at the estimate."
    body = f"<p class='decision'><b>{html.escape(text)}</b>"
    for w in warnings:
        body += f"<br><span class='bad'>{html.escape(w)}</span>"
    return body + "</p>"


def write_report(path: str | Path, sections: list[str] | None = None, title: str = "calib report",
                 results: Mapping[str, CalibrationResult] | None = None,
                 figures: Mapping[str, Mapping[str, Mapping[str, Path]]] | None = None,
                 intro: str = "", extra_figures: Mapping[str, Mapping[str, Path]] | None = None,
                 checks: Mapping[str, Mapping[str, str]] | None = None) -> Path:
    """Write a self-contained HTML report.

    Parameters
    ----------
    path : str or Path
        Output ``.html`` file (written to a temporary name in its folder, then renamed).
    sections : list of str, optional
        Pre-rendered HTML sections.
    results : mapping name -> CalibrationResult, optional
        Rendered with :func:`result_section`, using ``figures[name]``.
    intro : str
        Plain text paragraph under the title.
    extra_figures : mapping name -> {format: path}
        Figures shown at the top (e.g. comparisons). Figures are embedded as PNG, or as SVG
        when no PNG was written.
    checks : mapping name -> {label: statement}, optional
        Extra statements per result (e.g. coverage of a known truth).
    """
    body = [f"<h1>{html.escape(title)}</h1>"] + [decision_html(r) for r in (results or {}).values()]
    if intro:
        body.append(f"<p>{html.escape(intro)}</p>")
    if results and len(results) > 1:
        body.append("<h2>Comparison</h2>" + _table(
            ["calibration", "channels", "retained θ", "identified", "χ²/dof before", "χ²/dof after", "failed"],
            [(html.escape(n), html.escape(", ".join(r.channels)), r.n_retained, r.verdict_counts()["identified"],
              _fmt(r.chi2_per_dof_before), _fmt(r.chi2_per_dof_after),
              r.fit.failures.get("total_failed_point_evaluations", 0)) for n, r in results.items()]))
    for name, paths in (extra_figures or {}).items():
        body.append(_figure_html(name, paths))
    body += list(sections or [])
    for name, r in (results or {}).items():
        body.append(result_section(r, (figures or {}).get(name), (checks or {}).get(name)))
    text = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body>" + "\n".join(body) + "</body></html>")
    return atomic_write_text(path, text)
