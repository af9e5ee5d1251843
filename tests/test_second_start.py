"""The automatic choice's second start (``CalibrationSettings.second_start``): a fit whose χ²
rejects the stated noise is started again from the prior limit's count, and the better of the
two starts is kept by the one-standard-error rule across them."""

import numpy as np
import pytest
from test_calibration import CHANNELS, twin_truth
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.result import second_start_sentence
from calib.calibration.result_files import load_result
from calib.calibration.truncated_fit import TruncatedFit
from calib.calibration.truncation import keep_second_start
from calib.measurements import synthesize
from calib.report.result_sentences import sentences


class TrappedAtOne(TruncatedFit):
    """A first start that settles on one θ, as the loop from nominal did on coverage twin (d)
    seed 8319 (7 θ at χ²/dof 9.1; docs/user_guide/calibration.md); the second start chooses as usual."""

    in_second = False

    def second_start(self, *args):
        self.in_second = True
        return super().second_start(*args)

    def svd(self, problem, lin):
        if not self.in_second:
            self.truncation.frozen = 1
        return super().svd(problem, lin)


def trapped_at_one(model, meas, settings) -> Calibrator:
    """A Calibrator whose truncated estimator is :class:`TrappedAtOne`."""
    cal = Calibrator(model, meas, settings)
    cal.fitter = TrappedAtOne(cal)
    return cal


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
    return CalibrationSettings(estimator="truncated", **{"sigma_bar": "auto", "cd_min": None, "prior_check": False,
                                  "curvature_samples": 0, "second_start": True, **kw})


def test_a_first_start_trapped_at_few_theta_is_replaced_by_the_start_from_the_prior_limit(twin, tmp_path):
    model, meas = twin
    trapped = trapped_at_one(model, meas, _settings(second_start=False)).run()
    assert trapped.n_retained == 1 and "second_retained" not in trapped.identifiability.truncation
    model.jacobian_points.clear()
    cal = trapped_at_one(model, meas, _settings())
    res = cal.run()
    t = res.identifiability.truncation
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
    sentence = next(s for s in sentences(res) if "started again" in s)
    assert "ended at 1 θ" in sentence and f"at {res.n_retained} θ" in sentence and "the second was kept" in sentence
    assert "started again" in res.summary()
    res.save(tmp_path)
    back = load_result(tmp_path)
    assert {k: back.identifiability.truncation[k] for k in t if k.startswith(("first", "second"))} == \
        pytest.approx({k: t[k] for k in t if k.startswith(("first", "second"))})


def test_a_fit_the_stated_noise_explains_is_not_started_again(twin):
    model, meas = twin
    cal = Calibrator(model, meas, _settings())
    res = cal.run()
    gof = res.goodness_of_fit()
    assert gof["p_value_after"] >= 0.01, gof
    assert not any(k.startswith("second") for k in res.identifiability.truncation)
    assert not any(r.get("stage") == "second_start" for r in cal.history)


def test_no_second_start_with_noise_from_the_residuals(twin):
    """With ML noise χ²/dof is 1 by construction: there is no test to reject it."""
    model, meas = twin
    res = trapped_at_one(model, meas, _settings(noise="ml")).run()
    assert "second_retained" not in res.identifiability.truncation and res.n_retained == 1


def test_second_start_must_be_a_boolean():
    with pytest.raises(Exception, match="second_start"):
        CalibrationSettings(estimator="truncated", second_start="yes").validate()


@pytest.mark.parametrize("first, second, kept", [
    # both settled: the fewer θ unless the other's criterion is lower by more than its SE
    ((12, 1.53, 0.16, "converged"), (20, 1.40, 0.15, "converged"), False),
    ((12, 1.53, 0.16, "converged"), (20, 1.30, 0.15, "converged"), True),
    ((20, 1.40, 0.15, "converged"), (12, 1.53, 0.16, "converged"), True),
    ((20, 1.30, 0.15, "converged"), (12, 1.53, 0.16, "converged"), False),
    # equal counts and statuses: the first
    ((17, 1.60, 0.20, "not_stable"), (17, 1.50, 0.20, "not_stable"), False),
    # only one settled: that one is the default, whatever the counts
    ((17, 1.60, 0.20, "not_stable"), (17, 1.62, 0.20, "converged"), True),      # coverage twin (d), seed 8302
    ((17, 1.50, 0.20, "converged"), (22, 1.45, 0.20, "not_stable"), False),
    ((17, 1.50, 0.20, "converged"), (22, 1.20, 0.20, "not_stable"), True),      # clearly better: kept anyway
    ((22, 1.45, 0.20, "not_stable"), (17, 1.50, 0.20, "converged"), True),
    ((22, 1.20, 0.20, "not_stable"), (17, 1.50, 0.20, "converged"), False),
    # a failed second start, or one without a criterion, never
    ((17, 9.0, 2.0, "converged"), (22, 1.2, 0.2, "failed"), False),
    ((17, 9.0, 2.0, "converged"), (22, float("nan"), 0.2, "converged"), False),
])
def test_which_start_is_kept(first, second, kept):
    assert keep_second_start(first, second) is kept


def test_the_sentence_says_which_start_settled_when_only_one_did():
    t = {"first_retained": 17, "first_cv": 1.6, "first_cv_se": 0.2, "first_p_value": 1e-4, "first_status": "not_stable",
         "second_retained": 17, "second_cv": 1.62, "second_cv_se": 0.2, "second_status": "converged",
         "second_kept": 1}
    text = second_start_sentence(t)
    assert "ended at 17 θ (criterion 1.6 ± 0.2, not stable)" in text and "(1.62 ± 0.2, converged)" in text
    assert "the second was kept (the one whose retained set settled" in text
    same = {**t, "first_status": "converged"}
    assert "not stable" not in second_start_sentence(same) and "(the first, at the same count" in \
        second_start_sentence({**same, "second_kept": 0})
    # a result saved before the statuses were recorded
    old = {k: v for k, v in t.items() if not k.endswith("_status")}
    assert "converged" not in second_start_sentence(old)
