"""What the report figures show: every retained eigenshape, α on the node range, residual
panels, the fit's abscissa, parameter-labelled correlations, a known truth, progress."""

import dataclasses
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image
from twin_model import RADIUS, TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.measurements import synthesize
from calib.report import eigenshape_figures
from calib.report import figures as F
from calib.report.correlation_figure import display_order
from calib.report.eigenshape_figures import seen_inside
from calib.report.fit_figures import fit_abscissa, whitened_residual
from calib.report.polar_figures import station_columns
from calib.types import nominal_vector


@pytest.fixture(scope="module")
def result():
    model = TwinModel(channels=("power", "thrust", "root_flap_moment"))
    p_true = nominal_vector(model.parameters)
    n = model.grid.n_lift
    p_true[:n] = 0.05 * np.sin(np.arange(n))
    meas = synthesize(model, p_true, twin_conditions(),
                      relative_sigma={"power": 0.005, "thrust": 0.005, "root_flap_moment": 0.005}, seed=2)
    return Calibrator(model, meas, CalibrationSettings(sigma_bar=0.3), name="twin").run()


def _title(fig) -> str:
    return " ".join(fig._suptitle.get_text().split())


def _map_titles(fig) -> list[str]:
    return [t.get_text() for ax in fig.axes for t in ax.texts if t.get_text().startswith("θ")]


def test_every_retained_eigenshape_is_drawn_and_counted(result):
    # more retained directions than the 12 the old figure drew
    many = result.replace(identifiability=dataclasses.replace(result.identifiability, retained=np.ones(result.n_params,
                                                                                                       bool)))
    assert many.n_retained > 12
    for block in ("lift", "drag"):
        fig = F.plot_eigenshapes(many, block)
        titles = _map_titles(fig)
        assert titles == [f"θ{i + 1}" + t.split(f"θ{i + 1}", 1)[1] for i, t in enumerate(titles)]
        assert len(titles) == many.n_params
        assert f"all {many.n_params} retained θ" in _title(fig)
    fig = F.plot_eigenshapes(many, "lift", max_modes=5)
    assert len(_map_titles(fig)) == 5 and f"the first 5 of {many.n_params} retained θ" in _title(fig)


def test_eigenshape_maps_stay_on_the_node_range(result):
    grid = result.layout.grid
    # the data see α beyond the last node (up to 80 deg here): they are counted, not drawn
    wide = result.replace(fit=dataclasses.replace(result.fit, alpha_seen=np.concatenate([result.fit.alpha_seen,
                                                                                         [50.0, 65.0,
                                                                                          80.0]]), eta_seen=np.concatenate([result.fit.eta_seen, [0.5, 0.6, 0.7]])))
    a_in, e_in, n_out = seen_inside(wide)
    assert n_out >= 3 and a_in.max() <= grid.alpha_nodes_deg[-1]
    fig = F.plot_eigenshapes(wide, "lift")
    assert f"{n_out} outside it" in _title(fig)
    ax = fig.axes[0]
    [dots] = [line for line in ax.lines if line.get_marker() == ","]
    assert dots.get_xdata().size == a_in.size * wide.n_retained
    # every drawn point lies inside its tile: [col (1 + gap), col (1 + gap) + 1] in tile units
    x = dots.get_xdata()
    ncol = eigenshape_figures.MAX_COLUMNS
    gap = eigenshape_figures.MARGINS.wgap / eigenshape_figures.PANEL_SIZE[0]
    tile = np.repeat(np.arange(wide.n_retained) % ncol, a_in.size)
    u = x - tile * (1 + gap)
    assert u.min() >= -1e-9 and u.max() <= 1 + 1e-9
    assert ax.get_xlim()[1] == pytest.approx(ncol + (ncol - 1) * gap)     # the tiles across, nothing beyond


def _lines(fig, kind):
    """{(row, col): Line2D} of the polar figure's lines of one kind (gid "kind:row:col")."""
    return {tuple(int(v) for v in line.get_gid().split(":")[1:]): line for ax in fig.axes for line in ax.lines
            if (line.get_gid() or "").startswith(kind + ":")}


def test_polar_axes_cover_the_node_range_only(result):
    wide = result.replace(fit=dataclasses.replace(result.fit, alpha_seen=np.concatenate([result.fit.alpha_seen,
                                                                                         [80.0]]), eta_seen=np.concatenate([result.fit.eta_seen, [0.6]])))
    fig = F.plot_polars(wide)
    n = min(5, wide.layout.grid.eta_nodes.size)
    gap = 0.15 / 2.6
    assert [ax.get_ylabel() for ax in fig.axes] == ["C_L [-]", "C_D [-]"]
    for ax in fig.axes:
        assert ax.get_xlim() == pytest.approx((0, n + (n - 1) * gap))         # n tiles, nothing beyond
    calibrated = _lines(fig, "calibrated")
    assert sorted(calibrated) == [(r, c) for r in (0, 1) for c in range(n)]
    for (row, col), line in calibrated.items():
        # the node range [alpha_0, alpha_1] fills its tile exactly
        assert (line.get_xdata().min(), line.get_xdata().max()) == pytest.approx((col * (1 + gap), col * (1 + gap) + 1))
    titles = [t.get_text() for t in fig.axes[0].texts if t.get_text().startswith("η")]
    assert len(titles) == n and any("α seen" in t and "80°" in t for t in titles)


def _xlabel(fig) -> str:
    return next(t.get_text() for t in fig.axes[0].texts if t.get_gid() == "xlabel")


def test_each_fit_panel_has_a_residual_strip_under_it(result):
    fig = F.plot_fit(result)
    # loads of 1.5e4 to 7.3e4 in W, N and N m are drawn in kW, kN and kN m
    assert result.channel_units == ["W", "N", "N m"]
    assert [ax.get_ylabel() for ax in fig.axes] == ["power [kW]", "thrust [kN]", "root_flap_moment [kN m]"]
    r = whitened_residual(result)
    for k, ax in enumerate(fig.axes):
        [strip] = [line for line in ax.lines if line.get_gid() == f"residual:{k}"]
        np.testing.assert_array_equal(strip.get_xdata(), fit_abscissa(result)[0])   # same abscissa
        y = strip.get_ydata()                         # axes fraction: under the plotting area (y < 0)
        assert y.max() < 0
        # an increasing affine map of the whitened residual, nothing clipped or reordered
        slope, offset = np.polyfit(r[:, k], y, 1)
        assert slope > 0
        np.testing.assert_allclose(y, offset + slope * r[:, k], atol=1e-12)
        frame = [p for p in ax.patches if not p.get_fill()][0]
        assert frame.get_y() <= y.min() and y.max() <= frame.get_y() + frame.get_height()
        assert frame.get_y() + frame.get_height() < 0


def test_fit_abscissa_follows_the_rotor_speed(result):
    # twin conditions: rotor speed varies between points -> wind speed
    x, label, reason = fit_abscissa(result)
    assert np.ptp(result.conditions["rotor_speed"]) > 0
    np.testing.assert_array_equal(x, result.conditions["wind_speed"])
    assert label.startswith("wind speed") and "varies" in reason
    assert _xlabel(F.plot_fit(result)).startswith("wind speed")
    # constant rotor speed and a known radius -> tip-speed ratio
    cond = dict(result.conditions)
    cond["rotor_speed"] = np.full_like(cond["wind_speed"], 20.0)
    sweep = result.replace(provenance=dataclasses.replace(result.provenance, rotor_radius=RADIUS), conditions=cond)
    x, label, _ = fit_abscissa(sweep)
    np.testing.assert_allclose(x, 20.0 * np.pi / 30 * RADIUS / cond["wind_speed"])
    assert label.startswith("tip-speed ratio")
    assert _xlabel(F.plot_fit(sweep)).startswith("tip-speed ratio")
    # constant rotor speed, radius unknown -> wind speed, and the reason says why
    x, label, reason = fit_abscissa(sweep.replace(provenance=dataclasses.replace(sweep.provenance, rotor_radius=None)))
    assert label.startswith("wind speed") and "radius unknown" in reason


def test_correlation_axes_are_labelled_by_parameter(result):
    order, groups = display_order(result)
    assert sorted(order) == list(range(result.n_params))
    assert groups[0].start == 0 and groups[-1].stop == result.n_params
    assert all(a.stop == b.start for a, b in zip(groups, groups[1:]))
    fig = F.plot_correlation(result)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_yticklabels()]
    grid = result.layout.grid
    assert labels[:grid.alpha_nodes_deg.size] == [f"ΔC_L α={a:g}°" for a in grid.alpha_nodes_deg]
    assert "ΔC_D α=-4°" in labels and "pitch_offset" in labels
    assert not any(t.strip().isdigit() for t in labels)                        # no index numbers
    assert [t.get_text() for t in ax.get_xticklabels()] == labels
    # the matrix is drawn in the labelled order
    drawn = ax.images[0].get_array()
    expected = np.asarray(result.identifiability.correlation)[np.ix_(order, order)]
    np.testing.assert_array_equal(np.ma.filled(drawn, np.nan), np.where(np.isfinite(expected), expected, np.nan))
    # each row sits in its group: the lift node at (alpha=8, eta=0.6) is inside the "alpha=8" group
    idx = int(result.layout.lift_index[2, 1])
    row = int(np.flatnonzero(order == idx)[0])
    [g] = [g for g in groups if g.start <= row < g.stop]
    assert g.label == "ΔC_L α=8°"


def _bands(fig):
    """{(row, col): (lowest, highest) y of the drawn 95 % band} of the polar figure."""
    out = {}
    for ax in fig.axes:
        for coll in ax.collections:
            gid = coll.get_gid() or ""
            if gid.startswith("band:"):
                y = np.concatenate([path.vertices[:, 1] for path in coll.get_paths()])
                out[tuple(int(v) for v in gid.split(":")[1:])] = (y.min(), y.max())
    return out


def test_polar_bands_drawn_are_the_bounded_bands_and_older_results_fall_back_to_the_half_width(result):
    """The figure draws the band's stated ends (the drag band bounded by C_D,min); a result saved
    before the bounded bands (no ``d*_lower``/``d*_upper``) gets ± the half width."""
    pb = dict(result.uncertainty.polar_bands)
    # ends that are not ± the half width (as where C_D,min cuts the drag band)
    pb["dcd_lower"] = np.asarray(pb["dcd"]) - 0.3 * np.asarray(pb["dcd_half_width"])
    result = result.replace(uncertainty=dataclasses.replace(result.uncertainty, polar_bands=pb))
    cols = station_columns(np.asarray(pb["eta"]), 5)
    drawn = _bands(F.plot_polars(result))
    assert sorted(drawn) == [(r, c) for r in (0, 1) for c in range(cols.size)]
    for (row, col), (lo, hi) in drawn.items():
        j, letter = cols[col], ("cl", "cd")[row]
        base = np.asarray(pb[f"{letter}0"])[j]
        assert lo == pytest.approx(np.min(base + np.asarray(pb[f"d{letter}_lower"])[j]))
        assert hi == pytest.approx(np.max(base + np.asarray(pb[f"d{letter}_upper"])[j]))
    old = result.replace(uncertainty=dataclasses.replace(result.uncertainty, polar_bands={k: v for k, v in pb.items()
                                                   if not k.endswith(("_lower", "_upper"))}))
    for (row, col), (lo, hi) in _bands(F.plot_polars(old)).items():
        j, letter = cols[col], ("cl", "cd")[row]
        base, d = np.asarray(pb[f"{letter}0"])[j], np.asarray(pb[f"d{letter}"])[j]
        hw = np.asarray(pb[f"d{letter}_half_width"])[j]
        assert (lo, hi) == pytest.approx((np.min(base + d - hw), np.max(base + d + hw)))


def test_known_truth_is_overlaid_on_the_polars(result):
    def truth(alpha_deg, eta):
        return 0.1 * np.sin(np.radians(alpha_deg)) * eta, 0.002 + 0 * alpha_deg

    fig = F.plot_polars(result, truth=truth)
    pb = result.uncertainty.polar_bands
    cols = station_columns(np.asarray(pb["eta"]), 5)
    lines = _lines(fig, "truth")
    assert sorted(lines) == [(r, c) for r in (0, 1) for c in range(cols.size)]
    for (row, col), line in lines.items():
        j = cols[col]
        letter = ("cl", "cd")[row]
        dtrue = truth(np.asarray(pb["alpha_deg"]), pb["eta"][j])[row]
        np.testing.assert_allclose(line.get_ydata(), np.asarray(pb[f"{letter}0"])[j] + dtrue)
        np.testing.assert_array_equal(line.get_xdata(), _lines(fig, "calibrated")[row, col].get_xdata())
    assert "truth" in _title(fig)
    assert not _lines(F.plot_polars(result), "truth")


def test_write_figures_reports_progress_and_writes_png_only_by_default(result, tmp_path):
    messages, existing = [], []

    def progress(text):
        messages.append(text)
        existing.append(sorted(p.name for p in tmp_path.glob("*.png")))

    paths = F.write_figures(result, tmp_path, progress=progress)
    assert existing[0] == []                                        # told before the first figure
    for name in paths:
        assert sum(f" {name} (" in m for m in messages) == 1       # one line per figure, with its time
    assert len(messages) == len(paths) + 2
    assert all(set(p) == {"png"} for p in paths.values())
    assert not list(tmp_path.glob("*.svg"))
    for p in paths.values():
        with Image.open(p["png"]) as im:
            im.load()


def test_svg_on_request_parses(result, tmp_path):
    paths = F.write_figures(result, tmp_path, formats=F.ALL_FORMATS)
    for p in paths.values():
        assert set(p) == {"png", "svg"}
        assert ET.parse(p["svg"]).getroot().tag.endswith("svg")


def test_write_figures_draws_the_truth_it_is_given(result, tmp_path, monkeypatch):
    seen = []
    original = F.plot_polars

    def spy(res, truth=None, **kw):
        seen.append(truth)
        return original(res, truth=truth, **kw)

    monkeypatch.setattr(F, "plot_polars", spy)

    def truth(alpha_deg, eta):
        return 0 * alpha_deg, 0 * alpha_deg

    F.write_figures(result, tmp_path, truth=truth, workers=1)     # the spy lives in this process
    assert seen == [truth]


def test_report_states_the_counts_and_embeds_svg_when_no_png(result, tmp_path):
    from calib.report.html import write_report

    paths = F.write_figures(result, tmp_path, formats=("svg",))
    text = write_report(tmp_path / "report.html", results={"twin": result}, figures={"twin": paths}).read_text()
    assert text.count("data:image/svg+xml;base64,") == len(paths) and "data:image/png" not in text
    assert result.estimator == "map"
    assert f"The {result.n_retained} directions the data determine better than the prior are drawn" in text
    assert f"{result.n_retained} of {result.n_params} directions above 1" in text
    assert "Against wind speed (rotor speed varies between the points)" in text
