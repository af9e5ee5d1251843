"""Numbers in words (calib.words): p-values below the float floor are never printed as 0."""

from calib.words import p_is, p_text


def test_p_values_below_the_floor_say_so():
    assert p_text(0.0) == "< 1e-16" and p_is(0.0) == "p < 1e-16"
    assert p_text(3e-300) == "< 1e-16"
    assert p_text(0.031) == "0.031" and p_is(0.031) == "p = 0.031"
    assert p_text(float("nan")) == "n/a"


def test_the_calibration_report_writes_no_zero_p_value():
    """A nominal model far off the data (χ² far beyond its dof): the report's sentence says p < 1e-16."""
    from calib.calibration import CalibrationSettings, Calibrator
    from calib.measurements import synthesize
    from calib.report.result_sentences import sentences
    from calib.types import nominal_vector
    from twin_model import TwinModel, twin_conditions

    model = TwinModel(channels=("power", "thrust"))
    p_true = nominal_vector(model.parameters)
    p_true[:model.grid.n_lift] = 0.2
    meas = synthesize(model, p_true, twin_conditions(), relative_sigma={"power": 0.002, "thrust": 0.002}, seed=1)
    res = Calibrator(model, meas, CalibrationSettings(prior_check=False, tightening=False)).run()
    assert res.goodness_of_fit()["p_value_before"] < 1e-16
    text = " ".join(sentences(res))
    assert "(nothing fitted, p < 1e-16)" in text, text[:400]
    assert "p = 0 " not in text and "p = 0)" not in text and "p = 0;" not in text
    # the report section: units and a plain sentence for every statistic it tabulates
    from calib.report.html import result_section
    section = result_section(res)
    assert ">whitened residual [σ]<" in section and '>unit</th>' in section
    assert "χ²/dof is the mean squared misfit in units of the noise" in section
    assert "<b>identified</b> when the data halve it at least" in section
    assert "directions the data determine better than the prior (s &gt; 1)" in section
    assert "s &gt; 1 means the measurements pin it down better than the prior did" in section
    assert ">RMS misfit after [unit]<" in section and ">noise σ [unit]<" in section
    # the truncated estimator's words say what θ and σ̄ are
    from calib.report.html import _directions_words
    assert "σ̄ is the largest standard deviation a retained θ may have" in _directions_words("truncated")
