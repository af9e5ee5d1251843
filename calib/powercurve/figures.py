"""Figures of a calibrated power curve: the curve with its band over the nominal model's, C_P(λ)
with its band, and the AEP with its budget. Plain matplotlib ``Figure`` objects (no pyplot state)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

__all__ = ["aep_figure", "cp_tsr_figure", "power_curve_figure"]


def power_curve_figure(pc) -> Figure:
    """Electrical power [MW] against wind speed: the calibrated curve, the draws' 5–95 % band, the
    ±1.645 σ band of every source combined, and the nominal model's curve."""
    eta, v = pc.generator_efficiency, pc.wind_speed
    fig = Figure(figsize=(7.5, 4.5))
    ax = fig.add_subplot()
    P = eta * pc.central.power / 1e6
    tot = pc.power_std_total() / 1e6
    ax.fill_between(v, P - 1.645 * tot, P + 1.645 * tot, color="C0", alpha=0.15, lw=0,
                    label="90 % band, all sources")
    if pc.n_draws > 1:
        ax.fill_between(v, eta * pc.draw_quantile("power", 0.05) / 1e6, eta * pc.draw_quantile("power", 0.95) / 1e6,
                        color="C0", alpha=0.35, lw=0, label=f"5–95 % of {pc.n_draws} posterior draws")
    ax.plot(v, P, "C0-", lw=1.8, label="calibrated")
    ax.plot(v, eta * pc.nominal.power / 1e6, "k--", lw=1.2, label="nominal model")
    out = np.array([bool(e) for e in pc.envelope])
    if out.any():
        ax.plot(v[out], P[out], "o", mfc="none", mec="C3", ms=5, label="outside the calibration envelope")
    ax.set_xlabel("hub-height wind speed [m/s]")
    ax.set_ylabel("electrical power [MW]")
    ax.set_title(f"Power curve at {pc.air_density:g} kg/m³")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig


def cp_tsr_figure(pc) -> Figure:
    """C_P and C_T against the tip-speed ratio of each bin, with the draws' 5–95 % band."""
    v = pc.wind_speed
    lam = pc.central.rotor_speed * np.pi / 30 * pc.rotor_radius / v
    lam_n = pc.nominal.rotor_speed * np.pi / 30 * pc.rotor_radius / v
    fig = Figure(figsize=(7.5, 4.5))
    axes = fig.subplots(1, 2)
    order = np.argsort(lam)
    for ax, q, label in zip(axes, ("cp", "ct"), ("C_P [-]", "C_T [-]")):
        if pc.n_draws > 1:
            ax.fill_between(lam[order], pc.draw_quantile(q, 0.05)[order], pc.draw_quantile(q, 0.95)[order],
                            color="C0", alpha=0.35, lw=0, label="5–95 % of the draws")
        ax.plot(lam[order], getattr(pc.central, q)[order], "C0.-", label="calibrated")
        on = np.argsort(lam_n)
        ax.plot(lam_n[on], getattr(pc.nominal, q)[on], "k.--", label="nominal")
        ax.set_xlabel("tip-speed ratio λ [-]")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Along the power curve (one point per bin)", fontsize=10)
    fig.tight_layout()
    return fig


def aep_figure(rows) -> Figure:
    """AEP P50 per wind distribution with the 1-σ of each source beside it."""
    fig = Figure(figsize=(8.5, 4.5))
    ax, bx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.2, 1]})
    names = [r["distribution"].replace("Rayleigh ", "R ") for r in rows]
    x = np.arange(len(rows))
    ax.bar(x, [r["p50_mwh"] / 1e3 for r in rows], color="C0", label="calibrated P50")
    ax.errorbar(x, [r["p50_mwh"] / 1e3 for r in rows], yerr=[1.2816 * r["sigma_total_mwh"] / 1e3 for r in rows],
                fmt="none", ecolor="k", capsize=3, label="P50 − P90")
    ax.plot(x, [r["nominal_aep_mwh"] / 1e3 for r in rows], "k_", ms=14, mew=2, label="nominal model")
    ax.set_xticks(x, names, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("AEP [GWh]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    sources = list(rows[0]["sigma_mwh"])
    bottom = np.zeros(len(rows))
    for i, s in enumerate(sources):
        # without draws the calibration's share is its delta-method value (as in the total)
        var = np.array([np.nan_to_num(r["sigma_mwh"][s] if np.isfinite(r["sigma_mwh"][s]) or s != "calibration (draws)"
                                      else r["sigma_calibration_delta_mwh"]) ** 2 for r in rows])
        tot = np.array([r["sigma_total_mwh"] ** 2 for r in rows])
        share = np.where(tot > 0, 100 * var / np.where(tot > 0, tot, 1), 0.0)
        bx.bar(x, share, bottom=bottom, color=f"C{i}", label=s)
        bottom += share
    bx.set_xticks(x, names, rotation=45, ha="right", fontsize=8)
    bx.set_ylabel("share of the AEP variance [%]")
    bx.legend(fontsize=7)
    fig.tight_layout()
    return fig
