"""Every report figure is readable at the width the reports show it (tests/figure_check.py):
no overlapping or cut-off text, no panel narrower than a readable width, no text too small,
no "1e6" at an axis end instead of a unit prefix. First the check itself, on figures made
to fail it; then the calibration, campaign, diagnosis and demo figures."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from figure_check import figure_problems
from matplotlib.figure import Figure
from test_report_figures import result  # noqa: F401  (the fixture)

from calib.demo import DEMO_DPI, plot_cp_surface, plot_power_curve
from calib.report import figures as F
from calib.report.diagnosis_figures import plot_candidates, plot_gap
from calib.report.panels import spread, tile_labels, unit_prefix
from calib.report.spectrum_figures import plot_spectra
from calib.report.validation_figures import plot_campaign


# ----------------------------------------------------------------------------- the check fails where it should
def test_the_check_fails_on_a_row_of_twelve_panels():
    fig = Figure(figsize=(50.4, 3.6))          # the old diagnosis gap figure: 12 panels of 4.2 in in one row
    for k in range(12):
        ax = fig.add_subplot(1, 12, k + 1)
        ax.plot([0, 1], [0, 1])
    problems = figure_problems(fig)
    assert sum("wide as shown" in p for p in problems) == 12, problems
    assert any("px high as shown" in p for p in problems)


def test_the_check_fails_on_tick_labels_of_neighbouring_tiles_running_together():
    fig = Figure(figsize=(5, 2))
    ax = fig.add_axes((0.1, 0.3, 0.8, 0.6))
    ax.set_xlim(0, 2.1)
    ax.set_xticks([])
    for x0, values in ((0.0, (-3.03, 8.22)), (1.1, (-3.03, 8.22))):
        for u, v in zip((0.0, 1.0), values):
            ax.text(x0 + u, -0.05, f"{v:g}", ha="center", va="top", fontsize=9, transform=ax.get_xaxis_transform())
    assert any(p.startswith("texts '8.22' and '-3.03' overlap") for p in figure_problems(fig))
    # the same values placed by tile_labels: the ends aligned inwards, nothing overlaps
    fig = Figure(figsize=(5, 2))
    ax = fig.add_axes((0.1, 0.3, 0.8, 0.6))
    ax.set_xlim(0, 2.1)
    ax.set_xticks([])
    for x0 in (0.0, 1.1):
        for u, text, ha in tile_labels([0.0, 1.0], [-3.03, 8.22], 0.8 * 5 / 2.1, 9):
            ax.text(x0 + u, -0.05, text, ha=ha, va="top", fontsize=9, transform=ax.get_xaxis_transform())
    assert figure_problems(fig) == []


def test_the_check_fails_on_a_scale_factor_a_cut_off_text_and_narrow_tiles():
    from matplotlib.collections import PatchCollection
    from matplotlib.patches import Rectangle

    fig = Figure(figsize=(6, 4))
    ax = fig.add_axes((0.15, 0.15, 0.8, 0.75))
    ax.plot([0, 1], [2.0e6, 5.1e6])
    ax.set_ylabel("power [W]")
    fig.text(0.9, 0.5, "a note running off the right edge")
    ax.add_collection(PatchCollection([Rectangle((k * 0.2, 0), 0.18, 1) for k in range(5)], gid="tiles",
                                      facecolor="none"))
    problems = figure_problems(fig)
    assert any("scale factor or offset '1e6'" in p for p in problems), problems
    assert any("cut off by the figure's edge" in p for p in problems), problems
    assert any(p.startswith("tiles of 5 are") for p in problems), problems


def test_unit_prefix_spread_and_tile_labels():
    assert unit_prefix("W", [2e5, -5.1e6, np.nan]) == (1e6, "MW")
    assert unit_prefix("N m", [3e4]) == (1e3, "kN m")
    assert unit_prefix("N", [999.0]) == (1.0, "N")
    assert unit_prefix("deg", [2e3]) == (1.0, "deg")
    assert unit_prefix("W", [np.nan]) == (1.0, "W")
    # labels already apart stay; crowded ones move just apart, within the range
    np.testing.assert_allclose(spread([0.0, 5.0, 10.0], 1.0, 0.0, 10.0), [0.0, 5.0, 10.0])
    np.testing.assert_allclose(spread([0.0, 9.8, 10.0], 1.0, 0.0, 10.0), [0.0, 9.0, 10.0])
    np.testing.assert_allclose(spread([0.0, 0.1, 0.2], 5.0, 0.0, 4.0), [0.0, 2.0, 4.0])
    # the ends inwards; an inner value too close to a neighbour is dropped
    placed = tile_labels([0.0, 0.05, 0.5, 1.0], [-4, -3, 8, 20], tile_width=2.0, fontsize=7)
    assert [(t, ha) for _, t, ha in placed] == [("-4", "left"), ("8", "center"), ("20", "right")]


# ----------------------------------------------------------------------------- the figures pass it
# ``result``: the twin calibration of tests/test_report_figures.py (its module-scoped fixture)


def _megawatt(result):
    """The same fit on a rotor a hundred times larger in load (power in MW, moments in MN m)."""
    k = 100.0
    return result.replace(fit=dataclasses.replace(result.fit, measured=result.fit.measured * k,
                                                  model_before=result.fit.model_before * k, model_after=result.fit.model_after * k, sigma=result.fit.sigma * k))


@pytest.mark.parametrize("variant", ["as fitted", "every direction retained", "megawatt rotor"])
def test_calibration_figures_are_readable(result, variant):
    r = {"as fitted": result,
         "every direction retained": result.replace(identifiability=dataclasses.replace(result.identifiability,
                                                                                        retained=np.ones(result.n_params, bool))),
         "megawatt rotor": _megawatt(result)}[variant]
    drawn = 0
    for name, make in F.FIGURES.items():
        fig = make(r)
        if fig is None:
            continue
        drawn += 1
        assert figure_problems(fig) == [], name
    assert drawn >= 6
    fit = F.plot_fit(r)
    if variant == "megawatt rotor":
        assert fit.axes[0].get_ylabel() == "power [MW]" and fit.axes[2].get_ylabel() == "root_flap_moment [MN m]"


def test_spectra_and_campaign_figures_are_readable(result):
    assert figure_problems(plot_spectra({"stage 1": result, "stage 2": result})) == []
    rng = np.random.default_rng(0)
    channels = ["power", "thrust"] + [f"cn@{e:.2f}" for e in (0.3, 0.47, 0.63, 0.8, 0.95)]
    units = {"power": "W", "thrust": "N"}
    wind = np.repeat([5.0, 7.0, 10.0, 13.0, 15.0, 20.0, 25.0], 2)
    scale = np.array([4.0e6, 6.0e5] + [1.2] * 5)
    nominal = scale * (0.5 + rng.random((wind.size, len(channels))))
    fig = plot_campaign(channels, nominal * 1.05, wind, nominal, nominal * 1.02, "rotational_augmentation",
                        {"hub loads": (nominal * 1.04, 0.03 * nominal)}, title="a campaign", units=units)
    assert figure_problems(fig) == []
    assert fig.axes[0].get_title() == "power [MW]" and fig.axes[1].get_title() == "thrust [kN]"


CANDIDATES = ["rotational_augmentation:chaviaropoulos_hansen", "rotational_augmentation:snel",
              "rotational_augmentation:du_selig", "pitch_offset", "wind_speed_scale", "wind_tunnel_blockage",
              "lift_offset", "tip_loss", "leading_edge_erosion:stall", "leading_edge_erosion:slope"]


def _diagnosis(n_channels: int, n_points: int = 8):
    """A diagnosis as the figures see it, with the Phase VI run's shape: 12 channels, ten candidates."""
    rng = np.random.default_rng(1)
    lam = np.linspace(1.5, 5.4, n_points)
    measured = 1e3 * (1 + rng.random((n_points, n_channels)))
    sigma = 0.02 * measured
    fits = [SimpleNamespace(name=name, effect=name.split(":")[0], bic=100.0 + dbic, significant=p < 0.01,
                            p_value=p, weight=w)
            for name, dbic, p, w in zip(CANDIDATES, [0, 6.3, 7.4, 17, 26, 29, 31, 31, 38, 38],
                                        [1.2e-8, 3.3e-7, 6.7e-7, 1.9e-4, 0.011, 0.068, 0.53, 0.64, 1, 1],
                                        [0.94, 0.04, 0.02] + [0.0] * 7)]
    return SimpleNamespace(
        channels=[f"cn@{k}" for k in range(n_channels)], find={"tip_speed_ratio": lam}, measured=measured,
        sigma=sigma, model_before=measured * (1 + 0.05 * rng.standard_normal((n_points, n_channels))),
        model_with_effects=measured * (1 + 0.01 * rng.standard_normal((n_points, n_channels))),
        model_after=measured * (1 + 0.01 * rng.standard_normal((n_points, n_channels))),
        effects=["rotational_augmentation"], effect="rotational_augmentation", candidates=fits,
        rounds=[{"verdict": "rotational_augmentation", "candidates": fits}])


@pytest.mark.parametrize("n_channels", [1, 2, 12])
def test_diagnosis_figures_are_readable(n_channels):
    d = _diagnosis(n_channels)
    gap = plot_gap(d)
    assert figure_problems(gap) == []
    assert len(gap.axes) == n_channels
    assert figure_problems(plot_candidates(d)) == []


def test_the_gap_figure_shows_with_effect_and_after_apart():
    """Where the recalibration changes nothing the two markers coincide: a hollow circle and a
    dot inside it, both visible (the old figure drew the dot under a filled circle)."""
    d = _diagnosis(2)
    d.model_after = d.model_with_effects
    ax = plot_gap(d).axes[0]
    styles = {line.get_label(): line for line in ax.lines if not line.get_label().startswith("_")}
    with_effect, after = styles["with rotational_augmentation"], styles["after recalibration"]
    assert with_effect.get_markerfacecolor() == "none"
    assert after.get_markersize() < with_effect.get_markersize()
    assert ax.lines.index(after) > ax.lines.index(with_effect)          # drawn on top


def test_the_candidates_figure_has_no_shifted_axis():
    ax = plot_candidates(_diagnosis(2)).axes[0]
    assert "+0.5" not in ax.get_xlabel()
    dots = ax.collections[-1].get_offsets()
    np.testing.assert_allclose(np.asarray(dots)[:, 0], [0, 6.3, 7.4, 17, 26, 29, 31, 31, 38, 38])


def test_demo_figures_are_readable():
    """The C_P surface hatches and names the region C_P < 0 (it was clipped to 0 without a word)."""
    tsr, pitch = np.linspace(2, 14, 13), np.linspace(-2, 20, 12)
    L, B = np.meshgrid(tsr, pitch)
    cp = 0.48 - 0.01 * (L - 7.4) ** 2 - 0.004 * (B + 0.5) ** 2 - 0.03 * B * L / 10      # negative at high pitch
    assert cp.min() < 0
    fig = plot_cp_surface("rotor", tsr, pitch, cp)
    assert figure_problems(fig, dpi=DEMO_DPI) == []
    assert any("C_P < 0" in t.get_text() for t in fig.axes[0].get_legend().get_texts())
    v = np.arange(3.0, 25.01, 1.0)
    fig = plot_power_curve(v, np.minimum(5e6, 400 * v ** 3), 1e5 * np.minimum(v, 11.4))
    assert figure_problems(fig, dpi=DEMO_DPI) == []

