"""The discrepancy-aware covariance (calib.calibration.discrepancy_scale, issue 41) on each path a prediction
takes: the native BEM and the bundled FMU (variant A, in-process), each with the MAP and the truncated
estimator, under a stated noise. The data are the conformance matrix's (tests/conformance.py) with a
6 % ripple in the wind speed put on the power, which neither model's parameters can take up: the χ² test
fires and a discrepancy process is fitted. The prediction is compared with the same prediction through the
recorded covariance (the function replaced by one that returns it): for the MAP the re-formed covariance at
k' ≤ k gives intervals no wider, narrower somewhere, and the prediction says so; for the truncated estimator
the covariance stays as recorded, the prediction is the same bit for bit and says so."""

import dataclasses

import numpy as np
import pytest
from conformance import _case, build_model, conditions_of

import calib.calibration.prediction as prediction
from calib.calibration.discrepancy import fit_discrepancy
from calib.calibration.discrepancy_scale import EstimateCovariance, discrepancy_aware_covariance
from calib.calibration.settings import CalibrationSettings
from calib.calibration.calibrator import Calibrator


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    return tmp_path_factory.mktemp("scale_paths")


def _misfit(meas):
    """The measurements with the power multiplied by 1 + 0.06 sin(1.5 V) (V the wind speed [m/s]): a ripple
    shorter than the conditions the parameters act over."""
    j = list(meas.channels).index("power")
    values = meas.values.copy()
    values[:, j] *= 1.0 + 0.06 * np.sin(1.5 * np.asarray(meas.conditions.wind_speed, float))
    return dataclasses.replace(meas, values=values)


def _recorded(result, disc) -> EstimateCovariance:
    """The result's recorded covariance, as before the discrepancy-aware one (the comparison's baseline)."""
    k = float(result.uncertainty.fit_scale)
    return EstimateCovariance(np.asarray(result.uncertainty.cov_p, float), k, k, float("nan"), False, "")


@pytest.mark.parametrize("estimator", ["map", "truncated"])
@pytest.mark.parametrize("model_kind", ["bem_field", "fmu_a"])
def test_the_prediction_counts_the_misfit_once_on_each_path(model_kind, estimator, workdir, monkeypatch):
    _, meas = _case(model_kind, str(workdir))
    model, prior_std = build_model(model_kind, "default", None, workdir)
    try:
        settings = CalibrationSettings(estimator=estimator, noise="known", prior_std=prior_std or None)
        res = Calibrator(model, _misfit(meas), settings, name=f"{model_kind}-{estimator}").run()
        disc = fit_discrepancy(res)
        assert "power" in disc.processes, disc.words()
        est = discrepancy_aware_covariance(res, disc)
        k = float(res.uncertainty.fit_scale)
        cond = conditions_of(model_kind)
        pred = res.predict(cond, model)
        monkeypatch.setattr(prediction, "discrepancy_aware_covariance", _recorded)
        before = res.predict(cond, model)
    finally:
        if model_kind.startswith("fmu"):
            model.close()
    assert np.all(pred.status == 0) and np.all(np.isfinite(pred.std))
    if estimator == "map":
        assert k > 1.0 and est.reformed and 1.0 <= est.fit_scale < k
        assert "re-formed" in pred.discrepancy and f"k = {k:.3g}" in pred.discrepancy
        assert np.all(pred.std <= before.std * (1 + 1e-9)) and np.any(pred.std < before.std * (1 - 1e-3))
    else:
        assert not est.reformed and est.cov_p is res.uncertainty.cov_p
        np.testing.assert_array_equal(pred.std, before.std)         # the same covariance on the same path
        if k > 1.0:
            assert "not re-formed" in pred.discrepancy
