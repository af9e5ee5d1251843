"""The χ² gate before the localization (issue 38): with a stated noise the nominal model is
tested first, and the correction field is fitted only when the naming or the recalibration needs
it, once (seeds 9602 and 9604 as in tests/test_diagnosis.py, 9605 used nowhere else).

Baselines are independent of the diagnosis's code: the χ² of the nominal model from the model's
own outputs and the stated σ, and the recalibration from a fresh fit of the correction field
with the known noise (what the recalibration ran before it reused the localization).
"""

import dataclasses
import json

import numpy as np
import pytest
from scipy import stats
from test_diagnosis import GRID, SETTINGS, campaign, hidden

from calib.calibration import CalibrationSettings
from calib.calibration.calibrator import Calibrator
from calib.diagnosis.bem_family import BemFamily
from calib.diagnosis.core import diagnose
from calib.diagnosis.settings import DiagnosisSettings
from calib.report.diagnosis_report import write_diagnosis
from calib.rotor.library import load_rotor

KNOWN = CalibrationSettings(cd_min=0.003, noise="known")


def _diagnose(meas, cal=KNOWN, **diag):
    """The diagnosis and the labels of the models it built, in order."""
    labels = []

    def wrap(model, label):
        labels.append(label)
        return model

    d = diagnose(load_rotor("nrel5mw"), meas, GRID, SETTINGS, cal, DiagnosisSettings(**diag), wrap=wrap)
    return d, labels


@pytest.fixture(scope="module")
def quiet():
    """A 0.4 % wind-speed scale under 1 % noise: the nominal model passes the gate (p ≈ 0.26)."""
    rotor = load_rotor("nrel5mw")
    return hidden({"wind_speed_scale": {"wind_scale": 1.004}}, campaign(rotor), 9602)


def test_a_model_that_passes_the_gate_is_not_localized(quiet, tmp_path):
    d, labels = _diagnose(quiet, recalibrate=False, model_form_tolerance=0.0)
    assert labels == ["nominal"]                         # no field model built, let alone fitted
    assert d.effect == "none" and d.candidates == [] and d.localization is None
    assert d.recalibration is None
    # χ² against the stated σ, from the nominal model's own outputs
    y0 = BemFamily(load_rotor("nrel5mw"), list(quiet.channels), GRID, SETTINGS).nominal_model().evaluate(
        np.zeros(0), quiet.conditions).values
    chi2 = float(np.sum(((quiet.values - y0) / quiet.sigma) ** 2))
    assert d.before["chi2"] == pytest.approx(chi2, rel=1e-12)
    assert d.before["p_value"] == pytest.approx(stats.chi2.sf(chi2, quiet.values.size), rel=1e-9)
    np.testing.assert_array_equal(d.sigma, quiet.sigma)
    assert d.channel_units == ["W", "N", "N m", "N/m"]
    # the report and diagnosis.json say the localization did not run
    write_diagnosis(d, tmp_path)
    assert json.loads((tmp_path / "diagnosis.json").read_text())["localization"] is None
    html = (tmp_path / "report.html").read_text()
    assert "Localization (correction field alone): not run" in html
    assert "power " in html and " W" in html


def test_a_recalibration_on_the_nominal_model_is_the_localization_fit_once(quiet):
    d, labels = _diagnose(quiet, recalibrate=True, model_form_tolerance=0.0)
    assert labels == ["nominal", "localization"]          # one field fit, no second one
    assert d.effect == "none" and d.recalibration is d.localization
    # what the recalibration fitted before: the field on the nominal model, the known σ
    family = BemFamily(load_rotor("nrel5mw"), list(quiet.channels), GRID, SETTINGS)
    fresh = Calibrator(family.field_model(), quiet, dataclasses.replace(KNOWN, estimator="truncated", sigma=None),
                       name="recalibration").run()
    np.testing.assert_allclose(d.recalibration.estimate.p_hat, fresh.estimate.p_hat, rtol=1e-9, atol=1e-12)
    assert d.recalibration.n_retained == fresh.n_retained
    assert d.after["chi2"] == pytest.approx(float(np.sum(((quiet.values - fresh.fit.model_after) / quiet.sigma) ** 2)),
                                            rel=1e-9)
    assert d.after["chi2"] <= d.before["chi2"]


def test_a_model_that_fails_the_gate_is_localized_then_named_then_recalibrated():
    """A 1 % wind-speed scale (seed 9604) fails the gate: the field is fitted for the naming's
    pattern agreement, the effect named, and the recalibration on top of it is a fit of its own."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"wind_speed_scale": {"wind_scale": 1.01}}, campaign(rotor), 9604)
    d, labels = _diagnose(meas, recalibrate=True, max_effects=1, candidates=("wind_speed_scale", "pitch_offset"))
    assert d.effect == "wind_speed_scale"
    assert labels[:2] == ["nominal", "localization"] and labels.count("localization") == 1
    assert labels.count("recalibration") == 1 and d.recalibration is not d.localization
    assert np.isfinite([c.pattern_agreement for c in d.candidates]).all()


def test_an_estimated_noise_is_localized_first():
    """With noise = "ml" the σ comes from the localization: it runs before the nominal model's χ²."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({}, campaign(rotor), 9605)
    d, labels = _diagnose(meas, cal=dataclasses.replace(KNOWN, noise="ml"), recalibrate=False,
                          candidates=("pitch_offset",))
    assert labels[:2] == ["localization", "nominal"]
    np.testing.assert_array_equal(d.sigma, d.localization.fit.sigma)
