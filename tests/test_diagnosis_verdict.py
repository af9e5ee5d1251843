"""The naming round's verdict (calib.diagnosis.verdict.judge_round) on hand-made candidate fits:
a best fit held on the bound where part of its effect is off stands in for another effect."""

from __future__ import annotations

import pytest

from calib.diagnosis.result import CandidateFit
from calib.diagnosis.settings import DiagnosisSettings
from calib.diagnosis.verdict import judge_round


def _param(name, value, nominal, lower, upper, at_bound=""):
    return {"name": name, "value": value, "std": 0.01, "unit": "-", "nominal": nominal, "lower": lower,
            "upper": upper, "at_bound": at_bound}


def _fit(name, effect, bic, params):
    return CandidateFit(name=name, parameters=params, n_params=len(params), chi2=bic, loglik=-bic / 2, bic=bic,
                        lr_statistic=1e4, p_value=1e-12, significant=True, effect=effect,
                        at_bound=[q["name"] for q in params if q["at_bound"]], effect_text="-3 % power")


def _erosion(drag_rise, at_bound):
    return _fit("leading_edge_erosion:slope", "leading_edge_erosion", 5446.0,
                [_param("erosion_onset", 0.78, 0.8, 0.5, 0.98),
                 _param("erosion_drag_rise", drag_rise, 0.0, 0.0, 0.05, at_bound),
                 _param("erosion_lift_loss", 0.46, 0.0, 0.0, 1.0)])


def _tip_loss():
    return _fit("tip_loss", "tip_loss", 20916.0, [_param("tip_loss_strength", 1.7, 1.0, 0.0, 3.0)])


def _judge(fits):
    return judge_round(fits, 1e6, [], DiagnosisSettings(), lambda a, b: {"text": "probe"})


def test_erosion_that_wants_its_drag_lowered_stands_in_for_another_effect():
    rnd, named = _judge([_erosion(0.0, "lower"), _tip_loss()])
    assert named.effect == "tip_loss" and rnd["verdict"] == "tip_loss"
    assert "it stands in for another effect" in rnd["reason"] and "erosion_drag_rise = 0" in rnd["reason"]


@pytest.mark.parametrize("case", ["drag rise inside its bounds", "no other effect inside its bounds"])
def test_the_best_fit_is_named_otherwise(case):
    if case == "drag rise inside its bounds":
        fits = [_erosion(0.004, ""), _tip_loss()]
    else:
        tip = _tip_loss()
        tip.parameters[0].update(value=3.0, at_bound="upper")
        tip.at_bound = ["tip_loss_strength"]
        fits = [_erosion(0.0, "lower"), tip]
    rnd, named = _judge(fits)
    assert named.effect == "leading_edge_erosion" and "stands in" not in rnd["reason"]
