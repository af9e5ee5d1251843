"""The HTML report of a diagnosis (:func:`calib.diagnosis.core.diagnose`); its figures are
drawn by :mod:`calib.report.diagnosis_figures`.

- where the gap is: whitened residuals of each channel against tip-speed ratio (or wind
  speed), nominal / with the named effect(s) / after the recalibration;
- what was named on what evidence: ΔBIC and likelihood-ratio p-value of every candidate,
  with the named one marked;
- how much the gap shrank: χ²/dof and per-channel RMS before and after.

Every candidate's fit status is shown, and a fitted parameter at a bound
(:func:`calib.diagnosis.candidate_parameters.bound_side`) is marked "at lower/upper bound"; a diagnosis that
stopped early (``Diagnosis.failure``) says so at the top of the page.
"""

from __future__ import annotations

import base64
import html
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from calib.calibration.result_io import jsonable as _jsonable
from calib.report.atomic import atomic_write_text
from calib.report.diagnosis_figures import write_figures
from calib.words import p_is, p_text


def _table(header, rows, numbers=()) -> str:
    """An HTML table in its scroll box; cells wrap at spaces only, never inside a word, and the
    columns in ``numbers`` are right-aligned on one line ("< 1e-16" does not break at its minus)."""
    th = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f'<td class="n">{c}</td>' if j in numbers else f"<td>{c}</td>"
                                    for j, c in enumerate(row)) + "</tr>" for row in rows)
    return f'<div class="table"><table><tr>{th}</tr>{body}</table></div>'


def _parameter_text(q: dict) -> str:
    """"name = value ± std unit", with "(at lower bound)" / "(at upper bound)" when it is."""
    value = 0.0 if abs(q["value"]) <= 1e-9 * abs(q["std"]) else q["value"]   # round-off about zero reads 0
    # a minus sign (U+2212) in the exponent: no line break inside the number
    text = f"{q['name']} = {value:.4g} ± {q['std']:.2g}".replace("e-", "e\u2212") + _unit(q)
    return text + (f" (at {q['at_bound']} bound)" if q.get("at_bound") else "")


def _unit(q: dict) -> str:
    """" unit" of a parameter record, "" for a dimensionless one ("-" or no unit)."""
    return "" if q.get("unit") in ("", "-", None) else f" {q['unit']}"


def gap_words(d) -> str:
    """Where the nominal model misses, in engineering terms: the channel whose measured-minus-model
    gap is largest relative to the model (on max(|y|, 0.1 max|y|), so that a point of small load
    does not dominate), its sign, how large at most, and the tip-speed-ratio range of the points
    that miss beyond twice their noise; "" when the nominal model passes the χ² test (a few points
    beyond 2σ are then chance) or no point misses."""
    if d.before.get("p_value", 0.0) >= 0.01:
        return ""
    meas, nom, sig = np.asarray(d.measured, float), np.asarray(d.model_before, float), np.asarray(d.sigma, float)
    lam = np.asarray(d.find.get("tip_speed_ratio", []), float)
    best = None
    for j, c in enumerate(d.channels):
        ok = np.isfinite(nom[:, j])
        miss = ok & (np.abs(meas[:, j] - nom[:, j]) > 2.0 * sig[:, j])
        if not miss.any():
            continue
        size = np.maximum(np.abs(nom[:, j]), 0.1 * np.max(np.abs(nom[ok, j])))
        rel = (meas[:, j] - nom[:, j]) / np.where(ok & (size > 0), size, np.inf)
        k = int(np.flatnonzero(miss)[np.argmax(np.abs(rel[miss]))])
        if best is None or abs(rel[k]) > abs(best[1]):
            best = (c, float(rel[k]), miss)
    if best is None:
        return ""
    c, rel, miss = best
    where = ""
    if lam.size == miss.size:
        lo, hi, all_lo, all_hi = lam[miss].min(), lam[miss].max(), lam.min(), lam.max()
        where = (" at every tip-speed ratio" if np.isclose(lo, all_lo) and np.isclose(hi, all_hi) else
                 f" below λ {hi:.2g}" if np.isclose(lo, all_lo) else f" above λ {lo:.2g}" if np.isclose(hi, all_hi)
                 else f" at λ {lo:.2g}–{hi:.2g}")
    verb = "exceeds" if rel > 0 else "falls short of"
    return f"Measured {c.replace('_', ' ')} {verb} the model by up to {100 * abs(rel):.0f} %{where}"


def decision_words(d) -> str:
    """The decision first, in engineering terms: where the model misses, the best explanation with
    its fitted strength, and the runner-up's distance; or why nothing was named."""
    gap = gap_words(d)
    last = d.rounds[-1] if d.rounds else {}
    fits = sorted(last.get("candidates", []), key=lambda f: f.bic)
    if d.effect == "none" and d.model_form and fits:
        # only the model's own form was named: say so, with the fitted strength
        named = [g for r in d.rounds for g in r.get("candidates", []) if g.effect in d.model_form
                 and g.effect == r.get("verdict")]
        text = ((gap + "; " if gap else "") + "no physical effect is named; the misfit is the model's form "
                "(its induction model): " + "; ".join(_with_strength(g) for g in named[:2]))
        return text[0].upper() + text[1:].rstrip(".") + "."
    if d.effect == "none" or not fits:
        text = ((gap + "; " if gap else "") + "no effect is named: " +
                (last.get("reason", "the nominal model is consistent with the noise") if last else
                 "the nominal model is consistent with the noise"))
        return text[0].upper() + text[1:].rstrip(".") + "."
    text = gap + "; " if gap else ""
    if d.effect == "ambiguous":
        # the best fit of each of the two effects the last round could not tell apart
        pair = [next((g for g in fits if g.effect == e), None) for e in d.ambiguous]
        pair = [g for g in pair if g is not None]
        after = f"after {', '.join(d.effects)}, " if d.effects else ""
        text += f"{after}ambiguous between " + " and ".join(_with_strength(g) for g in pair)
        if len(pair) == 2:
            text += f" (ΔBIC {round(pair[1].bic - pair[0].bic, 2):g})"
        return text + "."
    f = ([g for g in fits if g.name in (d.effects or [d.effect])] or fits[:1])[0]
    text += f"best explanation: {_with_strength(f)}"
    rival = next((g for g in fits if g is not f), None)
    if rival is not None:
        text += f"; runner-up {rival.name}, ΔBIC {rival.bic - f.bic:.3g}"
    return text + "."


def _with_strength(f) -> str:
    """A candidate's name and its fitted parameters with their σ: "pitch_offset (pitch_offset 1.01 ± 0.027 deg)"."""
    strength = "; ".join(f"{q['name']} {q['value']:.3g} ± {q['std']:.2g}"
                         + ("" if q.get("unit") in ("", "-", None) else f" {q['unit']}") for q in f.parameters)
    return f"{f.name} ({strength})" if strength else f.name


class CandidateRow(NamedTuple):
    """One candidate in the candidate table: a main row and the detail line under it (HTML-escaped)."""

    round_no: int
    cells: tuple        # candidate, ΔBIC, BIC weight, Λ, significant, effect size, fitted value ± σ
    detail: str         # the full effect-size sentence, the parameters by name, χ², k, BIC, p, fit status
    named: bool         # the round named this candidate (or one of the two of an ambiguous verdict)


#: The candidate table's columns (:func:`_candidate_rows` fills them).
CANDIDATE_HEADER = ("candidate", "ΔBIC", "BIC weight", "Λ", "significant", "effect size", "fitted value ± σ")


#: Their cells' classes: a name on one line, numbers right-aligned, room for two fitted values a line.
_CANDIDATE_CLASSES = ("id", "n", "n", "n", "", "", "fit")


def _named_in(rnd: dict) -> set:
    """Names of the candidates a round named: the one its reason starts with, or for an ambiguous
    verdict the best significant candidate of each of the two effects."""
    fits = rnd["candidates"]
    if rnd.get("verdict") == "ambiguous":
        best = (next((f for f in fits if f.significant and f.effect == e), None) for e in rnd.get("ambiguous", []))
        return {f.name for f in best if f is not None}
    return {f.name for f in fits if rnd.get("reason", "").startswith(f"{f.name}: ")}


def _short_effect(text: str) -> str:
    """The effect size without where and against what, HTML: "+6.4 % thrust" of "+6.4 % thrust at
    19.8 m/s (tolerance 0.24 %)", the line breaking between the size and the channel only (the whole
    text when it has no " at ")."""
    size, _, channel = text.split(" at ", 1)[0].partition(" % ")
    return f"{_unbroken(size + ' %')} {html.escape(channel)}" if channel else _unbroken(size)


def _short_value(q: dict) -> str:
    """A fitted parameter without its name: "1.03 ± 0.026", "1.4 ± 0.19 deg", or "0 at bound"
    (the bound's value: on a bound the estimate is the bound, not an estimate)."""
    if q.get("at_bound"):
        return f"{q.get(q['at_bound'], q['value']):.3g}{_unit(q)} at bound"
    return f"{q['value']:.3g} ± {q['std']:.2g}{_unit(q)}"


def _unbroken(text: str) -> str:
    """``text`` HTML-escaped in a span the line never breaks inside ("1.03 ± 0.026" stays whole)."""
    return f'<span class="nb">{html.escape(text)}</span>'


def _chi2_change(x: float) -> str:
    """A change of χ² (ΔBIC, Λ) for a reader: one decimal below 100, none above."""
    return f"{x:.1f}" if abs(x) < 100 else f"{x:.0f}"


def _candidate_rows(d) -> list[CandidateRow]:
    """Every candidate of every round, in the rounds' order (best BIC first): the main row, short
    enough for one or two lines, and the long text for the detail line under it."""
    rows = []
    for r_no, rnd in enumerate(d.rounds):
        named = _named_in(rnd)
        best = min((f.bic for f in rnd["candidates"]), default=0.0)
        for f in rnd["candidates"]:
            cells = (html.escape(f.name), _chi2_change(f.bic - best), f"{f.weight:.3f}", _chi2_change(f.lr_statistic),
                     "yes" if f.significant else "no", _short_effect(f.effect_text),
                     ", ".join(_unbroken(_short_value(q)) for q in f.parameters))
            fit = f.status or "?"
            if f.start:
                fit += f"; {f.start}"
            detail = (f"{f.effect_text}. Fitted (1σ): {'; '.join(_parameter_text(q) for q in f.parameters)}. "
                      f"χ² {f.chi2:.4g} with k = {f.n_params}, BIC {f.bic:.4g}, {p_is(f.p_value)}, pattern agreement "
                      f"{f.pattern_agreement:.2f}. Fit: {fit}.")
            rows.append(CandidateRow(r_no + 1, cells, html.escape(detail), f.name in named))
    return rows


def _round_title(rnd: dict, r_no: int) -> str:
    """"round 1: rotational_augmentation", "round 2, on top of rotational_augmentation: none"."""
    base = f", on top of {', '.join(rnd['base'])}" if rnd.get("base") else ""
    return f"round {r_no}{base}: {rnd.get('verdict', '?')}"


def _candidate_table(d) -> str:
    """The candidate table: per round a title row, then per candidate a main row (the named one in
    bold) and a detail line under it."""
    n = len(CANDIDATE_HEADER)
    head = "".join(f"<th>{html.escape(h)}</th>" for h in CANDIDATE_HEADER)
    body, last = [], 0
    for row in _candidate_rows(d):
        if row.round_no != last:
            last = row.round_no
            title = _round_title(d.rounds[last - 1], last)
            body.append(f'<tr class="round"><th colspan="{n}">{html.escape(title)}</th></tr>')
        cells = "".join(f'<td class="{cls}">{c}</td>' for cls, c in zip(_CANDIDATE_CLASSES, row.cells))
        body.append(f'<tr class="candidate{" named" if row.named else ""}">{cells}</tr>'
                    f'<tr class="detail"><td colspan="{n}">{row.detail}</td></tr>')
    return f'<div class="table"><table class="candidates"><tr>{head}</tr>{"".join(body)}</table></div>'


# Cells wrap at spaces only, so a name never breaks inside; the candidate table keeps its main rows
# short and puts the long text on a detail line under each; a table still too wide scrolls inside its
# own box, never the page (tests/test_browser_report.py fails when any table needs to at 1100 px).
_CSS = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}"
        ".table{overflow-x:auto;max-width:100%;margin:.5em 0 1.2em}table{border-collapse:collapse;font-size:.9em}"
        "td,th{border:1px solid #ccc;padding:3px 7px}th{background:#f0f0f0}"
        "td.n{text-align:right;white-space:nowrap}td.id,.nb{white-space:nowrap}td.fit{min-width:12em}"
        "tr.named td{font-weight:bold}tr.named td,tr.named+tr.detail td{background:#eef5ee}"
        "tr.round th{text-align:left;background:#e4e4e4}tr.candidate td{border-bottom-style:hidden}"
        "tr.detail td{font-size:.85em;color:#555;padding:0 7px 5px 1.6em}"
        "img{max-width:100%;height:auto}.failed{background:#fde8e8;padding:.5em}")


def write_diagnosis(d, out_dir: str | Path, progress=None) -> dict[str, Path]:
    """Write ``diagnosis.json``, the figures and ``report.html`` into ``out_dir`` (atomically)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    text = json.dumps(_jsonable(d.to_dict()), indent=1, allow_nan=True)
    atomic_write_text(out / "diagnosis.json", text)
    paths["json"] = out / "diagnosis.json"
    figs = write_figures(d, out, progress or (lambda s: None))
    body = _summary_html(d) + _evidence_html(d, figs) + _gap_html(d, figs) + _closing_html(d)
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>calib diagnose</title><style>{_CSS}</style>"
            f"</head><body>{''.join(body)}</body></html>")
    atomic_write_text(out / "report.html", page)
    paths["report"] = out / "report.html"
    return paths


def _img(p: Path) -> str:
    """An ``<img>`` of the PNG file ``p``, embedded as base64."""
    return f'<img alt="{p.stem}" src="data:image/png;base64,{base64.b64encode(p.read_bytes()).decode()}">'


def _summary_html(d) -> list[str]:
    """The page's title, the decision in words, an early stop, and χ²/dof through the steps."""
    form = f" (model form: {', '.join(d.model_form)})" if d.model_form else ""
    body = [f"<h1>calib diagnose: {html.escape(d.effect + form)}</h1>",
            f"<p class='decision'><b>{html.escape(decision_words(d))}</b></p>"]
    failure = d.failure
    if failure:
        body.append(f'<p class="failed"><b>Stopped early:</b> {html.escape(failure)}. What the rounds before '
                    "found is reported below.</p>")
    named = ", ".join(e + (" (model form)" if e in d.model_form else "") for e in d.effects) or "none"
    if d.ambiguous:
        named += f" (the last round: ambiguous between {' and '.join(d.ambiguous)}, neither added)"
    steps = f"χ²/dof {d.before['chi2_per_dof']:.3g} (nominal)"
    if d.effects:     # the model with the named effects differs from the nominal one only when one was added
        steps += f" → {d.with_effects['chi2_per_dof']:.3g} (with the effect{'s' if len(d.effects) > 1 else ''})"
    steps += f" → {d.after['chi2_per_dof']:.3g} (after recalibrating the correction field)"
    body.append(f"<p>Named effect(s): <b>{html.escape(named)}</b>. {html.escape(steps)}. "
                f"Wall time {d.wall_time:.1f} s.</p>")
    return body


def _evidence_html(d, figs: dict[str, Path]) -> list[str]:
    """Why each round named what it did: the reasons, the candidate table explained, its figure."""
    reasons = "".join(f"<li>round {k + 1}: {html.escape(r['reason'])}</li>" for k, r in enumerate(d.rounds))
    return [f"<h2>Evidence</h2><ul>{reasons}</ul>",
            _candidate_table(d),
            ("<p class='explain'>How to read the table: one row per candidate, best first in each round, the "
             "one the round named in bold on green; the grey line under it holds the full effect size, the "
             "fitted parameters by name, χ², k, BIC, p and the fit status. <b>χ²</b> is the misfit of the "
             "candidate's fit, whitened by the noise; <b>k</b> its number of fitted parameters. <b>BIC</b> = "
             "χ² + k ln N charges each parameter; lower is better, <b>ΔBIC</b> is the distance to the round's "
             "best, and the <b>BIC weight</b> is the candidate's share of the evidence among all candidates and "
             "no effect (1 = all of it). <b>Λ</b> (likelihood ratio) is how much the candidate lowers χ² "
             "against the model without it; <b>p</b> is how likely so large a drop is by chance if the "
             "candidate were not there (χ² with k degrees of freedom), and <b>significant</b> compares it with "
             "the significance level shared among the candidates (and the effect size with the model-form "
             "tolerance). The <b>effect size</b> is the largest change of an output the candidate makes. The "
             "<b>pattern agreement</b> is the correlation between how the candidate changes the outputs and "
             "how the free correction field changes them (1 = the same shape, 0 = unrelated). A fitted value "
             "at its bound is flagged: it is the bound the data push against, not an estimate.</p>"),
            _img(figs["candidates"])]


def _gap_html(d, figs: dict[str, Path]) -> list[str]:
    """Where the nominal model misses (trends per channel, the residual figure) and how much the
    misfit shrank with the named effect(s) and the recalibration."""
    units = dict(zip(d.channels, d.channel_units)) if d.channel_units else (
        dict(zip(d.localization.channels, d.localization.channel_units)) if d.localization is not None else {})
    gap_rows = [(html.escape(label), f"{g['chi2_per_dof']:.3g}", g["dof"], html.escape(p_text(g['p_value'])),
                 html.escape(", ".join(f"{c} {v:.4g} {units.get(c, '')}".rstrip() for c, v in g["rms"].items())))
                for label, g in (("nominal", d.before), ("with " + (", ".join(d.effects) or "no effect"),
                                                         d.with_effects),
                                 ("after recalibration" if d.recalibration is not None
                                  else "no recalibration (as above)", d.after))]
    trend_rows = [(html.escape(c), f"{t['chi2_per_point']:.3g}", f"{t['mean_whitened']:+.2f}",
                   f"{t['corr_tip_speed_ratio']:+.2f}", f"{t['corr_pitch']:+.2f}", f"{t['corr_wind_speed']:+.2f}",
                   f"{t['corr_load_level']:+.2f}") for c, t in d.find["trends"].items()]
    return ["<h2>Where the gap is</h2>",
            _table(["channel", "χ²/point nominal", "mean whitened residual", "corr. with λ", "corr. with pitch",
                    "corr. with wind speed", "corr. with load level"], trend_rows, numbers=range(1, 7)),
            _img(figs["gap"]),
            "<h2>How much it shrank</h2>",
            _table(["model", "χ²/dof", "dof", "p-value", "RMS per channel (measured − model)"], gap_rows,
                   numbers=(1, 2, 3)),
            ("<p class='explain'>χ²/dof near 1 means the model explains the measurements to within their noise; "
             "the p-value is the chance of a misfit at least this large if it did.</p>")]


def _closing_html(d) -> list[str]:
    """The localization by the correction field alone, an empty recalibration, the notes and the set-up."""
    if d.localization is None:
        body = ["<p>Localization (correction field alone): not run. The nominal model passes the χ² test "
                "against the stated noise, so there is no disagreement to localize.</p>"]
    else:
        body = [(f"<p>Localization (correction field alone): {d.localization.n_retained} θ retained, χ²/dof "
                 f"{d.localization.chi2_per_dof_after:.3g} (a θ is one combination of polar corrections the data "
                 f"determine; its eigenshape says where on the (α, r/R) plane it acts).</p>")]
    rec = d.recalibration
    if rec is not None and rec.n_retained == 0:
        body.append("<p>The recalibration retained 0 θ: nothing is left that the correction field explains "
                    "beyond the named effect(s).</p>")
    if d.notes:
        body.append("<ul>" + "".join(f"<li>{html.escape(n)}</li>" for n in d.notes) + "</ul>")
    if d.setup:
        from calib.report.setup_statement import statement_html
        body.append(statement_html(d.setup))
    return body
