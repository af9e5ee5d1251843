"""The problem statement (issue 36, item 2): built once by the Calibrator, the one owner of the nominal
values, scales, effective bounds, prior and channel columns that the estimators' problem, the
uncertainty terms and the result read; frozen, its arrays read-only."""

import dataclasses

import numpy as np
import pytest
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.problem import LeastSquaresProblem, ProblemStatement
from calib.calibration.uncertainty_terms import ModelTerms
from calib.measurements import synthesize
from calib.types import nominal_vector

STATED = ("parameters", "p0", "scale", "lower", "upper", "prior_std", "prior_stated", "channel_index")


@pytest.mark.parametrize("estimator", ["map", "truncated"])
def test_the_statement_is_the_one_owner_of_the_problem(estimator):
    model = TwinModel(channels=("power", "thrust"))
    p0 = nominal_vector(model.parameters)
    meas = synthesize(model, p0, twin_conditions(), channels=("thrust",), relative_sigma={"thrust": 0.01}, seed=3)
    cal = Calibrator(model, meas, CalibrationSettings(estimator=estimator, cd_min=0.003, prior_check=False,
                                                      tightening=False, curvature_samples=0))
    problems = []
    finish = cal.fitter.finish

    def spy(problem, *args):
        problems.append(problem)
        return finish(problem, *args)

    cal.fitter.finish = spy
    res = cal.run()
    statement = cal.statement
    # one object: the estimators' problem and the uncertainty terms read it, the result's estimate is it
    assert problems[0].statement is statement and cal.terms.statement is statement
    assert problems[0].with_sigma(2.0 * problems[0].sigma).statement is statement
    for got, stated in ((res.estimate.p_nominal, statement.p0), (res.estimate.lower, statement.lower),
                        (res.estimate.upper, statement.upper), (res.estimate.scale, statement.scale),
                        (res.uncertainty.prior_std, statement.prior_std)):
        assert got is stated
    # what it states: the thrust column, the nominal values, the field's C_D bound applied to the bounds
    assert statement.channel_index == (1,)
    assert np.array_equal(statement.p0, p0)
    raw_lower = np.array([q.lower for q in model.parameters])
    assert np.all(statement.lower >= raw_lower) and np.any(statement.lower > raw_lower)
    assert res.provenance.settings["lower_effective"] == statement.lower.tolist()
    # and nobody else holds a copy
    for holder in (cal, cal.terms, problems[0]):
        assert not set(STATED) & set(vars(holder)), type(holder).__name__
    assert not set(STATED) & {f.name for f in dataclasses.fields(ModelTerms)}


def test_the_statement_is_frozen_and_checked():
    model = TwinModel(channels=("power",))
    qs = model.parameters
    n = len(qs)
    scale = np.array([q.scale for q in qs])
    lower = np.array([q.lower for q in qs])
    statement = ProblemStatement(qs, nominal_vector(qs), scale, lower, -lower, scale, np.zeros(n, bool), [0])
    with pytest.raises(dataclasses.FrozenInstanceError):
        statement.lower = lower
    for name in STATED[1:-1]:
        with pytest.raises(ValueError, match="read-only"):
            getattr(statement, name)[0] = 0
    lower[0] = -123.0                                   # a copy, not the caller's array
    assert statement.lower[0] != -123.0
    assert statement.channel_index == (0,) and isinstance(statement.parameters, tuple)
    with pytest.raises(ValueError, match="scale has 2 values"):
        ProblemStatement(qs, np.zeros(n), scale[:2], lower, -lower, scale, np.zeros(n, bool), [0])
    with pytest.raises(ValueError, match="parameters"):
        ProblemStatement(qs[:1], np.zeros(n), scale, lower, -lower, scale, np.zeros(n, bool), [0])
    problem = LeastSquaresProblem(model, twin_conditions(), np.zeros((1, 1)), np.ones((1, 1)), statement)
    assert np.array_equal(problem.unscaled(np.ones(n)), statement.p0 + scale)
