"""The automatic choice's second start (``CalibrationSettings.second_start``): a fit whose χ²
rejects the stated noise is started again from the prior limit's count, and the better of the
two starts is kept by the one-standard-error rule across them."""

import numpy as np
import pytest

from calib.calibration import CalibrationSettings, Calibrator
from calib.measurements import synthesize
from calib.report.html import _sentences
from calib.result import load_result
from test_calibration import CHANNELS, twin_truth
from twin_model import TwinModel, twin_conditions


class TrappedAtOne(Calibrator):
    """A first start that settles on one θ, as the loop from nominal did on coverage twin (d)
    seed 8319 (7 θ at χ²/dof 9.1; README); the second start chooses as usual."""

    in_second = False

    def _second_start(self, *args):
        self.in_second = True
        return super()._second_start(*args)

    def _svd(self, problem, lin):
        if not self.in_second:
            self._auto_frozen = 1
        return super()._svd(problem, lin)


class CountingTwin(TwinModel):
    """The analytic twin, recording the parameter vector of every Jacobian."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.jacobian_points = []

    def jacobian(self, p, conditions):
        self.jacobian_points.append(np.asarray(p, float).tobytes())
        return super().jacobian(p, conditions)


@pytest.fixture(scope="module")
def twin():
    model = CountingTwin(channels=CHANNELS)
    cond = twin_conditions()
    p_true = twin_truth(model)
    meas = synthesize(model, p_true, cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=4711)
    return model, meas


def _settings(**kw):
    return CalibrationSettings(**{"sigma_bar": "auto", "cd_min": None, "prior_check": False,
                                  "curvature_samples": 0, "second_start": True, **kw})


def test_a_first_start_trapped_at_few_theta_is_replaced_by_the_start_from_the_prior_limit(twin, tmp_path):
    model, meas = twin
    trapped = TrappedAtOne(model, meas, _settings(second_start=False)).run()
    assert trapped.n_retained == 1 and "second_retained" not in trapped.truncation
    model.jacobian_points.clear()
    cal = TrappedAtOne(model, meas, _settings())
    res = cal.run()
    t = res.truncation
    # the second start begins from the first's linearization at the start point, and the kept
    # start's last linearization is reused: no Jacobian is computed twice at the same point
    assert len(set(model.jacobian_points)) == len(model.jacobian_points)
    assert t["first_retained"] == 1 and t["first_p_value"] < 0.01
    assert t["second_kept"] == 1 and res.n_retained == t["second_retained"] > 1
    # kept because its criterion is lower by more than its standard error, each on its own curve
    assert t["second_cv"] + t["second_cv_se"] < t["first_cv"]
    assert np.isclose(t["second_cv"], np.asarray(t["cv"])[res.n_retained])
    assert res.chi2_per_dof_after < 0.5 * trapped.chi2_per_dof_after
    assert any(r.get("stage") == "second_start" for r in cal.history)
    sentence = next(s for s in _sentences(res) if "started again" in s)
    assert "settled on 1 θ" in sentence and f"on {res.n_retained} θ" in sentence and "the second was kept" in sentence
    assert "started again" in res.summary()
    res.save(tmp_path)
    back = load_result(tmp_path)
    assert {k: back.truncation[k] for k in t if k.startswith(("first", "second"))} == \
        pytest.approx({k: t[k] for k in t if k.startswith(("first", "second"))})


def test_a_fit_the_stated_noise_explains_is_not_started_again(twin):
    model, meas = twin
    cal = Calibrator(model, meas, _settings())
    res = cal.run()
    gof = res.goodness_of_fit()
    assert gof["p_value_after"] >= 0.01, gof
    assert not any(k.startswith("second") for k in res.truncation)
    assert not any(r.get("stage") == "second_start" for r in cal.history)


def test_no_second_start_with_noise_from_the_residuals(twin):
    """With ML noise χ²/dof is 1 by construction: there is no test to reject it."""
    model, meas = twin
    res = TrappedAtOne(model, meas, _settings(noise="ml")).run()
    assert "second_retained" not in res.truncation and res.n_retained == 1


def test_second_start_must_be_a_boolean():
    with pytest.raises(Exception, match="second_start"):
        CalibrationSettings(second_start="yes").validate()
