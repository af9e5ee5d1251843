"""The embedded default job: C_P(λ, β) surface and power curve of an embedded rotor."""

from __future__ import annotations

import csv
import json
import logging
import time
from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.bem.polar_grid import SectionPolars
from calib.bem.steady_control import cp_surface, steady_power_curve
from calib.logs import say
from calib.report.atomic import atomic_path, atomic_write_text
from calib.rotor.library import load_rotor, reference_path

log = logging.getLogger("calib.demo")


def _openfast_reference():
    """OpenFAST steady operating points of the NREL 5-MW (rows at 5 m/s and above)."""
    with open(reference_path("NREL5MW_Oper_openfast_sim.csv"), newline="") as fh:
        rows = [r for r in csv.DictReader(fh)]
    v = np.array([float(r["WS_[m/s]"]) for r in rows])
    keep = v >= 5.0
    def col(name, scale=1.0):
        return np.array([float(r[name]) for r in rows])[keep] * scale
    return {"wind_speed": v[keep], "rotor_speed": col("RotSpeed_[rpm]"), "pitch": col("BldPitch_[deg]"),
            "power": col("RotTorq_[kN-m]", 1e3) * col("RotSpeed_[rpm]") * np.pi / 30,
            "thrust": col("RtAeroFxh_[kN]", 1e3)}


def run_demo(out_dir: str | Path = "demo_output", rotor_name: str = "nrel5mw") -> dict:
    """Compute and plot the C_P(λ, β) surface and the steady power curve.

    Writes ``cp_surface.png``, ``power_curve.png`` and ``summary.json`` into ``out_dir``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rotor = load_rotor(rotor_name)
    polars = SectionPolars.from_rotor(rotor)
    say(log, f"[calib demo] rotor {rotor.name}: R = {rotor.tip_radius:.2f} m, {rotor.n_blades} blades, "
          f"{rotor.n_stations} stations")
    tsr = np.linspace(2.0, 14.0, 61)
    pitch = np.linspace(-2.0, 20.0, 45)
    t0 = time.perf_counter()
    cp, ct, res = cp_surface(rotor, tsr, pitch, polars=polars)
    t_surface = time.perf_counter() - t0
    say(log, f"[calib demo] C_P surface: {cp.size} points in {t_surface:.2f} s; {res.n_failed} failed")
    k = np.nanargmax(cp)
    i, j = np.unravel_index(k, cp.shape)
    # the surface includes the shaft tilt (BemSettings.use_tilt); an untilted rotor (CCBlade's comparison on the
    # speed page) reaches more: the wind's normal component scales by cos(tilt), the power by about cos³
    cp_untilted = float(np.nanmax(cp_surface(rotor, tsr, pitch, polars=polars,
                                             settings=BemSettings(use_tilt=False))[0])) if rotor.tilt_deg else None
    v = np.arange(3.0, 25.01, 0.5)
    curve = steady_power_curve(rotor, v, polars=polars)
    say(log, f"[calib demo] power curve: {v.size} wind speeds, {curve.result.n_failed} failed")

    fig = plot_cp_surface(rotor.name, tsr, pitch, cp)
    with atomic_path(out / "cp_surface.png") as tmp:
        fig.savefig(tmp, dpi=DEMO_DPI, format="png")
    fig = plot_power_curve(v, curve.result.power, curve.result.thrust,
                           _openfast_reference() if rotor_name == "nrel5mw" else None)
    with atomic_path(out / "power_curve.png") as tmp:
        fig.savefig(tmp, dpi=DEMO_DPI, format="png")

    summary = {"rotor": rotor.name, "cp_max": float(cp[i, j]), "tsr_at_cp_max": float(tsr[j]),
               "pitch_at_cp_max": float(pitch[i]), "surface_points": int(cp.size),
               "surface_failed": int(res.n_failed), "surface_seconds": t_surface,
               "power_curve_failed": int(curve.result.n_failed),
               "rated_wind_speed": float(v[np.argmax(curve.pitch > rotor.schedule.fine_pitch + 1e-6)]),
               "shaft_tilt_deg": float(rotor.tilt_deg), "cp_max_untilted": cp_untilted}
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2))
    say(log, f"[calib demo] max C_P = {summary['cp_max']:.4f} at λ = {summary['tsr_at_cp_max']:.2f}, "
          f"β = {summary['pitch_at_cp_max']:.1f} deg{_tilt_words(summary)}; figures in {out}/")
    return summary


DEMO_DPI = 130      # resolution of the demo's figures [1/in]


def plot_cp_surface(name: str, tsr: np.ndarray, pitch: np.ndarray, cp: np.ndarray):
    """C_P(λ, β) as filled contours with its maximum starred.

    Where C_P < 0 the rotor takes power from the shaft (it drives the air, at high λ and low
    pitch or at high pitch); that region is hatched and named instead of being shown as the
    lowest colour, and points the BEM could not solve (NaN) are counted in the title.

    Parameters
    ----------
    name : str
        Rotor name for the title.
    tsr : ndarray, shape (n_tsr,)
        Tip-speed ratios λ [-].
    pitch : ndarray, shape (n_pitch,)
        Blade pitch β [deg].
    cp : ndarray, shape (n_pitch, n_tsr)
        Power coefficient [-]; NaN where the solve failed.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    fig = Figure(figsize=(7, 5))
    ax = fig.add_axes((0.1, 0.11, 0.68, 0.8))
    i, j = np.unravel_index(np.nanargmax(cp), cp.shape)
    top = float(cp[i, j])
    cs = ax.contourf(tsr, pitch, cp, levels=np.linspace(0, top, 25), cmap="viridis")     # C_P < 0 left blank
    lines = ax.contour(tsr, pitch, cp, levels=[v for v in (0.1, 0.2, 0.3, 0.4, 0.45) if v < top], colors="w",
                       linewidths=0.6)
    ax.clabel(lines, fontsize=7, fmt="%g")
    handles = [ax.plot(tsr[j], pitch[i], "r*", ms=12, ls="none")[0]]
    labels = [f"max C_P = {top:.3f} at λ = {tsr[j]:.2f}, β = {pitch[i]:.1f}°"]
    if np.nanmin(cp) < 0:
        ax.contourf(tsr, pitch, cp, levels=[float(np.nanmin(cp)) - 1.0, 0.0], colors=["0.92"], hatches=["///"])
        handles.append(Patch(facecolor="0.92", hatch="///", edgecolor="0.5"))
        labels.append("C_P < 0: the rotor takes power from the shaft")
    failed = int(np.count_nonzero(~np.isfinite(cp)))
    cax = fig.add_axes((0.81, 0.11, 0.03, 0.8))
    # round ticks and the maximum, none so close to it that the labels touch (6 % of the bar's 4 in)
    fig.colorbar(cs, cax=cax, ticks=[v for v in np.arange(0.0, top, 0.05) if v < 0.94 * top] + [top],
                 format="%.3g")
    cax.set_ylabel("C_P [-] (C_P ≥ 0)")
    ax.set(xlabel="tip-speed ratio λ [-]", ylabel="pitch β [deg]",
           title=f"{name}: C_P(λ, β), native BEM" + (f"; {failed} points not solved (blank)" if failed else ""))
    ax.legend(handles, labels, loc="upper right", fontsize=8)
    return fig


def plot_power_curve(wind: np.ndarray, power: np.ndarray, thrust: np.ndarray, reference: dict | None = None):
    """Steady aerodynamic power [MW] and rotor thrust [kN] against wind speed, beside a reference.

    Parameters
    ----------
    wind : ndarray
        Wind speed [m/s].
    power, thrust : ndarray
        [W], [N].
    reference : dict, optional
        ``wind_speed`` [m/s], ``power`` [W] and ``thrust`` [N] of another code (OpenFAST).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.2))
    a1, a2 = fig.add_axes((0.07, 0.13, 0.4, 0.78)), fig.add_axes((0.57, 0.13, 0.4, 0.78))
    a1.plot(wind, power / 1e6, "-", label="native BEM, own schedule")
    a2.plot(wind, thrust / 1e3, "-", label="native BEM, own schedule")
    if reference is not None:
        a1.plot(reference["wind_speed"], reference["power"] / 1e6, "ko", ms=4, label="OpenFAST steady (aero)")
        a2.plot(reference["wind_speed"], reference["thrust"] / 1e3, "ko", ms=4, label="OpenFAST steady (aero)")
    a1.set(xlabel="wind speed [m/s]", ylabel="aerodynamic power [MW]", title="power curve")
    a2.set(xlabel="wind speed [m/s]", ylabel="rotor thrust [kN]", title="thrust curve")
    for a in (a1, a2):
        a.grid(alpha=0.3)
        a.legend()
    return fig


def _tilt_words(summary: dict) -> str:
    """Why the demo's maximum C_P differs from an untilted rotor's ("" for a rotor without tilt)."""
    if not summary.get("cp_max_untilted"):
        return ""
    return (f"; with the {summary['shaft_tilt_deg']:g}° shaft tilt, {summary['cp_max_untilted']:.4f} untilted as in "
            "the comparison with CCBlade")


#: What the embedded demo campaign hides (calib/data/demo_campaign/PROVENANCE.txt).
DEMO_HIDDEN = ("rotational augmentation (stall delay) in the Du & Selig (1998) form, strength 1 "
               "(stall_delay_strength = 1), which the nominal model lacks; 1 % noise")


def write_demo_report(out_dir: str | Path, summary: dict, diagnosis=None) -> Path:
    """``out_dir/report.html``: the C_P surface and power curve, what the demo data hide and how
    strong, and the diagnosis's decision with a link to its own report."""
    import base64
    import html

    out = Path(out_dir)

    def img(name):
        path = out / name
        return (f'<img alt="{path.stem}" style="max-width:100%" '
                f'src="data:image/png;base64,{base64.b64encode(path.read_bytes()).decode()}">')

    body = [f"<h1>calib demo: {html.escape(summary['rotor'])}</h1>",
            f"<p>Maximum C_P {summary['cp_max']:.4f} at λ {summary['tsr_at_cp_max']:.2f} and pitch "
            f"{summary['pitch_at_cp_max']:.1f}° ({summary['surface_points']} points, {summary['surface_failed']} "
            f"failed{_tilt_words(summary)}); rated wind speed {summary['rated_wind_speed']:.1f} m/s.</p>",
            img("cp_surface.png"), img("power_curve.png")]
    if diagnosis is not None:
        from calib.report.diagnosis_report import decision_words
        body += ["<h2>The diagnosis of the embedded test campaign</h2>",
                 f"<p>The campaign's data hide {html.escape(DEMO_HIDDEN)}.</p>",
                 f"<p><b>{html.escape(decision_words(diagnosis))}</b></p>",
                 '<p>The evidence, the candidates and the gap before and after: '
                 '<a href="diagnosis/report.html">diagnosis/report.html</a>.</p>']
    page = ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>calib demo</title><style>body{font-family:"
            "system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}</style></head><body>"
            + "".join(body) + "</body></html>")
    atomic_write_text(out / "report.html", page)
    return out / "report.html"
