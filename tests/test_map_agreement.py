"""The MAP estimate's self-check (calib.calibration.map_agreement): it fires on a prior that fixes what the
data determine and on a MAP that stopped short where the data dominate, and stays silent on a
correct MAP, computed here in closed form on a linear Gaussian problem."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from twin_model import TwinModel, twin_conditions

import calib.calibration.map_fit as calibration
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.map_agreement import AGREEMENT_Z, DOMINANT_S, map_ml_agreement
from calib.measurements import synthesize
from calib.types import nominal_vector

NAMES = ["gain_root", "gain_tip", "drag_add", "pitch_bias"]


def _linear(seed, n_rows=60, noise=1.0):
    """Whitened sensitivities of 4 scaled parameters, a prior draw of the truth and its data."""
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((n_rows, 4)) * np.array([30.0, 25.0, 8.0, 3.0])
    P = np.diag([1.0, 1.0, 0.5, 4.0]) ** 2
    x_true = np.linalg.cholesky(P) @ rng.standard_normal(4)
    y = M @ x_true + noise * rng.standard_normal(n_rows)
    return M, P, y


def _map(M, P, y):
    """The exact MAP of the linear problem and its whitened residual."""
    x = np.linalg.solve(M.T @ M + np.linalg.inv(P), M.T @ y)
    return x, y - M @ x


BOX = (np.full(4, -1e9), np.full(4, 1e9))


@pytest.mark.parametrize("seed", range(20, 30))
def test_a_correct_map_agrees_with_the_ml_where_the_data_dominate(seed):
    M, P, y = _linear(seed)
    x, r = _map(M, P, y)
    check = map_ml_agreement(M, r, x, P, *BOX, NAMES)
    assert check.ok and check.n_dominant >= 2 and check.n_data == 4, check
    assert check.max_z < AGREEMENT_Z
    assert "WARNING" not in check.sentence()


def test_an_outer_product_prior_fixes_what_the_data_determine():
    """Issue 34's prior: σσᵀ is rank one, so three of the four directions the data see are fixed."""
    M, P, y = _linear(3)
    sd = np.sqrt(np.diag(P))
    P_outer = np.outer(sd, sd)
    x, r = _map(M, P_outer + 1e-14 * np.eye(4), y)
    check = map_ml_agreement(M, r, x, P_outer, *BOX, NAMES)
    assert check.n_fixed == 3 and check.n_data == 4 and not check.ok
    assert "fixes 3 of the 4 direction(s)" in check.sentence() and "rank 1 where the sensitivities have 4" \
        in check.sentence()


def test_a_map_that_stopped_short_is_caught_and_named():
    """Planted: the estimate moved 3 ML σ off the MAP along the best-determined parameter."""
    M, P, y = _linear(7)
    x, r = _map(M, P, y)
    sd_ml = np.sqrt(np.diag(np.linalg.inv(M.T @ M)))
    x_bad = x.copy()
    x_bad[0] += 3.0 * sd_ml[0]
    check = map_ml_agreement(M, y - M @ x_bad, x_bad, P, *BOX, NAMES)
    assert not check.ok and check.max_z > 2.0 and "gain_root" in check.disagree, check
    # not a stationary point of the posterior either: the MAP's own gradient condition fails there
    assert np.linalg.norm(M.T @ (y - M @ x_bad) - np.linalg.solve(P, x_bad)) > 1.0


def test_a_parameter_held_at_its_bound_is_not_counted_as_disagreeing():
    """At an active bound the posterior gradient is not zero: the check conditions on the held parameter."""
    M, P, y = _linear(11)
    x, _ = _map(M, P, y)
    lower = np.full(4, -1e9)
    lower[1] = x[1] + 0.5           # the bound cuts the unconstrained MAP: gain_tip held there
    xb = x.copy()
    xb[1] = lower[1]
    free = [0, 2, 3]
    # the constrained MAP of the others given gain_tip at its bound (prior diagonal: independent)
    Mf, Pf = M[:, free], P[np.ix_(free, free)]
    xb[free] = np.linalg.solve(Mf.T @ Mf + np.linalg.inv(Pf), Mf.T @ (y - M[:, 1] * xb[1]))
    check = map_ml_agreement(M, y - M @ xb, xb, P, lower, np.full(4, 1e9), NAMES)
    assert check.ok and check.n_data == 3, check


def test_the_calibrator_warns_when_its_map_is_planted_off_the_maximum(monkeypatch):
    """The whole path: a MAP estimator that returns a point 5 σ off the maximum with status
    "converged" gets a warning in its message and its checks, naming the parameter."""
    model = TwinModel(channels=("power", "thrust"), nonlinearity=0.0, nuisance=("pitch_offset",))
    cond = twin_conditions()
    p0 = nominal_vector(model.parameters)
    meas = synthesize(model, p0, cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=4)
    settings = CalibrationSettings(estimator="map", prior_std={"pitch_offset": 0.3}, cd_min=None,
                                   representation_error=False, prior_check=False, scale_by_fit=False)
    honest = Calibrator(model, meas, settings).run()
    assert honest.estimate.status == "converged" and "WARNING" not in honest.estimate.message
    assert honest.provenance.checks["MAP and ML"].startswith("MAP and ML agree within")
    j = [q.name for q in model.parameters].index("pitch_offset")
    real = calibration.estimate_map

    def stopped_short(problem, *args, **kwargs):
        out = real(problem, *args, **kwargs)
        p = out.p.copy()
        p[j] += 5.0 * honest.uncertainty.std_p[j]
        return dataclasses.replace(out, p=p, linearization=problem.linearize(p), status="converged")

    monkeypatch.setattr(calibration, "estimate_map", stopped_short)
    planted = Calibrator(model, meas, settings).run()
    assert planted.estimate.status == "converged"
    assert "WARNING" in planted.estimate.message and "pitch_offset" in planted.provenance.checks["MAP and ML"], planted.provenance.checks
    assert f"s ≥ {DOMINANT_S:g}" in planted.provenance.checks["MAP and ML"]
