"""A self-contained HTML report (images embedded as base64 PNG) of one or more calibrations."""

from __future__ import annotations

import base64
import html
import os
from pathlib import Path
from typing import Mapping

import numpy as np

from calib.result import CalibrationResult

_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222;line-height:1.4}
table{border-collapse:collapse;margin:0.5em 0 1.2em}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}img{max-width:100%;margin:0.4em 0}
.bad{color:#b00}.ok{color:#070}h2{border-bottom:2px solid #ddd;padding-bottom:2px}
"""


def _img(path: Path) -> str:
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    return f'<img alt="{html.escape(Path(path).stem)}" src="data:image/png;base64,{data}">'


def _table(header, rows, left=1) -> str:
    th = "".join(f'<th class="{"l" if i < left else ""}">{html.escape(str(h))}</th>' for i, h in enumerate(header))
    body = ""
    for row in rows:
        body += "<tr>" + "".join(f'<td class="{"l" if i < left else ""}">{c}</td>' for i, c in enumerate(row)) + "</tr>"
    return f"<table><tr>{th}</tr>{body}</table>"


def _fmt(x, digits=4) -> str:
    if isinstance(x, (float, np.floating)):
        return f"{x:.{digits}g}"
    return html.escape(str(x))


def result_section(result: CalibrationResult, figures: Mapping[str, Mapping[str, Path]] | None = None) -> str:
    """HTML of one calibration: key numbers, verdicts, failures, figures."""
    r = result
    dof = max(r.dof, 1)
    status_cls = "ok" if r.status == "converged" else "bad"
    parts = [f"<h2>{html.escape(r.name)}</h2>",
             f'<p>Status: <b class="{status_cls}">{html.escape(r.status)}</b> — {html.escape(r.message)}. '
             f"Wall time {r.wall_time:.2f} s.</p>"]
    counts = r.verdict_counts()
    key = [("operating points", r.n_points), ("channels", ", ".join(r.channels)),
           ("parameters", r.n_params), ("retained θ (σ(θ) ≤ σ̄)", r.n_retained), ("σ̄ [scale units]", r.sigma_bar),
           ("χ²/dof before", r.chi2_before / dof), ("χ²/dof after", r.chi2_after / dof), ("dof", r.dof),
           ("optimizer", r.settings.get("optimizer")), ("noise", r.settings.get("noise"))]
    key += [(f"verdict: {k}", v) for k, v in counts.items()]
    parts.append(_table(["quantity", "value"], [(html.escape(k), _fmt(v)) for k, v in key]))
    fail = r.failures
    fail_cls = "bad" if fail.get("final", 0) or fail.get("total_failed_point_evaluations", 0) else "ok"
    parts.append(f'<p class="{fail_cls}">Failed model points: nominal {fail.get("nominal", 0)}, final '
                 f'{fail.get("final", 0)}, over all evaluations {fail.get("total_failed_point_evaluations", 0)} '
                 f'({fail.get("model_evaluations", 0)} evaluations, {fail.get("model_jacobians", 0)} '
                 f"Jacobians).</p>")
    rb, ra = r.rms("before"), r.rms("after")
    parts.append("<h3>Fit per channel</h3>" + _table(
        ["channel", "unit", "noise σ", "RMS before", "RMS after"],
        [(html.escape(c), html.escape(u), _fmt(float(s)), _fmt(rb[c]), _fmt(ra[c]))
         for c, u, s in zip(r.channels, r.channel_units, r.noise_sigma)]))
    # verdicts: non-correction parameters in full, correction nodes summarized
    rows = []
    for v in r.verdicts:
        if v["kind"] in ("lift_correction", "drag_correction") and v["verdict"] == "poorly observable":
            continue
        rows.append((html.escape(v["name"]), html.escape(v["verdict"]), _fmt(v["nominal"]), _fmt(v["value"]),
                     _fmt(v["std"]), _fmt(v["observability"], 2)))
    parts.append("<h3>Verdicts</h3><p>Identified / at-bound parameters and all nuisance parameters "
                 "(poorly observable correction nodes are frozen near nominal and omitted).</p>" +
                 _table(["parameter", "verdict", "nominal", "estimate", "std", "observability"], rows, left=2))
    if figures:
        parts.append("<h3>Figures</h3>")
        for name, paths in figures.items():
            if "png" in paths:
                parts.append(f"<h4>{html.escape(name.replace('_', ' '))}</h4>" + _img(paths["png"]))
    parts.append("<details><summary>Reproducibility</summary><pre>" + html.escape(
        "\n".join([f"inputs: {r.inputs}", f"versions: {r.versions}",
                   f"settings: { {k: v for k, v in r.settings.items() if k != 'lower_effective'} }"])) +
        "</pre></details>")
    return "\n".join(parts)


def write_report(path: str | Path, sections: list[str] | None = None, title: str = "calib report",
                 results: Mapping[str, CalibrationResult] | None = None,
                 figures: Mapping[str, Mapping[str, Mapping[str, Path]]] | None = None,
                 intro: str = "", extra_figures: Mapping[str, Mapping[str, Path]] | None = None) -> Path:
    """Write a self-contained HTML report.

    Parameters
    ----------
    path : str or Path
        Output ``.html`` file (written atomically).
    sections : list of str, optional
        Pre-rendered HTML sections.
    results : mapping name -> CalibrationResult, optional
        Rendered with :func:`result_section`, using ``figures[name]``.
    intro : str
        Plain text paragraph under the title.
    extra_figures : mapping name -> {format: path}
        Figures shown at the top (e.g. comparisons).
    """
    body = [f"<h1>{html.escape(title)}</h1>"]
    if intro:
        body.append(f"<p>{html.escape(intro)}</p>")
    if results and len(results) > 1:
        body.append("<h2>Comparison</h2>" + _table(
            ["calibration", "channels", "retained θ", "identified", "χ²/dof before", "χ²/dof after", "failed"],
            [(html.escape(n), html.escape(", ".join(r.channels)), r.n_retained, r.verdict_counts()["identified"],
              _fmt(r.chi2_before / max(r.dof, 1)), _fmt(r.chi2_after / max(r.dof, 1)),
              r.failures.get("total_failed_point_evaluations", 0)) for n, r in results.items()]))
    for name, paths in (extra_figures or {}).items():
        if "png" in paths:
            body.append(f"<h4>{html.escape(name.replace('_', ' '))}</h4>" + _img(paths["png"]))
    body += list(sections or [])
    for name, r in (results or {}).items():
        body.append(result_section(r, (figures or {}).get(name)))
    text = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{_CSS}</style></head><body>" + "\n".join(body) + "</body></html>")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".html.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    return path
