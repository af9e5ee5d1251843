"""Result serialization round trip, figures (PNG and SVG) and the self-contained HTML report."""

import dataclasses
import json
import re

import numpy as np
import pytest
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.result_files import load_result
from calib.calibration.result_parts import ARRAY_FIELDS
from calib.errors import InputError
from calib.measurements import synthesize
from calib.report import figures as F
from calib.report.html import write_report
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


@pytest.fixture(scope="module")
def figure_paths(result, tmp_path_factory):
    return F.write_figures(result, tmp_path_factory.mktemp("figures"), formats=("png",))


def test_result_round_trip(result, tmp_path):
    jpath, npath = result.save(tmp_path)
    back = load_result(tmp_path)
    # exact: save writes the arrays' bytes and load hands them back, no arithmetic in between
    for part, name in ARRAY_FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(getattr(back, part), name)),
                                      np.asarray(getattr(getattr(result, part), name)), err_msg=f"{part}.{name}")
    for k, v in result.conditions.items():
        np.testing.assert_array_equal(back.conditions[k], v)
    for k, v in result.uncertainty.polar_bands.items():
        np.testing.assert_array_equal(back.uncertainty.polar_bands[k], v)
    assert back.identifiability.verdicts == result.identifiability.verdicts and back.estimate.status == result.estimate.status
    assert back.n_retained == result.n_retained and back.summary() == result.summary()
    data = json.loads(jpath.read_text())
    assert {"estimate", "identifiability", "uncertainty", "fit", "provenance", "summary"} <= set(data)
    assert {"settings", "versions", "inputs"} <= set(data["provenance"]) and "verdicts" in data["identifiability"]
    assert "failures" in data["fit"] and {"numpy", "scipy", "casadi", "python"} <= set(data["provenance"]["versions"])
    assert load_result(jpath).n_params == result.n_params          # the file path works too


def test_load_result_names_the_missing_file(tmp_path):
    with pytest.raises(InputError, match="result.json"):
        load_result(tmp_path)


def test_every_figure_is_written(result, figure_paths, tmp_path):
    paths = figure_paths
    # the truncation curve exists only for sigma_bar = 'auto'
    assert set(paths) == set(F.FIGURES) - (set() if result.identifiability.truncation else {"truncation"})
    for p in paths.values():
        assert set(p) == {"png"}                                   # SVG only on request
        assert p["png"].stat().st_size > 5000
    svg = F.save_figure(F.plot_singular_values(result), tmp_path, "spectrum", formats=("svg",))["svg"]
    assert svg.read_text().lstrip().startswith("<?xml") and "<svg" in svg.read_text()[:2000]


def test_eigenshape_figure_has_one_map_per_retained_mode(result):
    fig = F.plot_eigenshapes(result, "drag")
    titles = [t.get_text() for ax in fig.axes for t in ax.texts if t.get_text().startswith("θ")]
    assert len(titles) == result.n_retained
    assert f"all {result.n_retained} retained θ" in " ".join(fig._suptitle.get_text().split())


def test_html_report_is_self_contained_with_key_numbers(result, figure_paths, tmp_path):
    figs = {"twin": figure_paths}
    path = write_report(tmp_path / "report.html", title="twin report", results={"twin": result}, figures=figs)
    text = path.read_text(encoding="utf-8")
    assert text.count("data:image/png;base64,") == len(figs["twin"])
    assert not re.search(r'src="(?!data:)', text)            # nothing loaded from elsewhere
    assert f"{result.n_retained}" in text and "χ²/dof after" in text
    assert "Failed model points" in text and result.estimate.status in text


def test_report_says_where_the_drag_band_starts_at_cd_min(result):
    """The sentence counts the polar figure's points where the ΔC_D band starts at C_D,min and
    is absent where none does (and for a result saved before the bounded bands)."""

    from calib.report.result_sentences import sentences

    pb = dict(result.uncertainty.polar_bands)
    cd_min = 0.004
    floor = np.minimum(cd_min - np.asarray(pb["cd0"]), 0.0)
    lower = np.asarray(pb["dcd_lower"], float).copy()
    lower.flat[:7] = floor.flat[:7]                              # seven points cut by the bound
    pb["dcd_lower"] = lower
    cut = result.replace(uncertainty=dataclasses.replace(result.uncertainty, polar_bands=pb),
                         provenance=dataclasses.replace(result.provenance, settings={**result.provenance.settings,
                                                                                     "cd_min": cd_min}))
    [text] = [t for t in sentences(cut) if "C_D,min" in t]
    assert text.startswith(f"The ΔC_D band starts at C_D,min = 0.004 at 7 of the {lower.size} points")
    none = cut.replace(uncertainty=dataclasses.replace(cut.uncertainty, polar_bands={**pb, "dcd_lower": floor - 1e-3}))
    assert not [t for t in sentences(none) if "C_D,min" in t]
    old = cut.replace(uncertainty=dataclasses.replace(cut.uncertainty, polar_bands={k: v for k,
                                                                                    v in pb.items() if k != "dcd_lower"}))
    assert not [t for t in sentences(old) if "C_D,min" in t]
