"""Predictions where the correction nodes do not reach: the interval is the prior's there.

A calibration on high tip-speed ratios (small angles of attack) with α nodes up to 8° predicts
a low tip-speed-ratio point whose sections sit at 15–30°, beyond the last node's hat. There the
correction field is the prior's: its interval must carry the variance of the outputs under
fields drawn from the smooth-field prior. That variance is measured here by Monte Carlo through
the nonlinear model (fields drawn on the fine grid, each evaluated), independently of the
linearized formula :func:`calib.calibration.prediction.field_between_nodes` uses.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.corrections import CorrectionGrid
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.parametrizations.aliasing import discrepancy_correlation, interpolation_matrix, refined_grid
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector

CHANNELS = ("power", "thrust")


@pytest.fixture(scope="module")
def calibrated():
    rotor = load_rotor("phase_vi")
    grid = CorrectionGrid([-4.0, 0.0, 4.0, 8.0], [0.3, 0.6, 1.0])
    model = BemModel(rotor, grid, CHANNELS, BemSettings(use_tilt=False), nuisance=())
    tsr, pitch = np.meshgrid([6.0, 7.0, 8.0, 9.0], [0.0, 2.0, 4.0], indexing="ij")
    v = 72 * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, 72.0), pitch.ravel())
    meas = synthesize(model, nominal_vector(model.parameters), cond, relative_sigma={c: 0.01 for c in CHANNELS},
                      seed=11)
    res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003)).run()
    far = OperatingConditions([72 * np.pi / 30 * rotor.rotor_radius / 1.6], [72.0], [0.0])    # λ 1.6: deep stall
    return model, res, far


def test_beyond_the_nodes_the_interval_is_the_prior_s(calibrated):
    model, res, far = calibrated
    assert res.estimate.status == "converged" and res.uncertainty.gain.size
    # the formula at the stated prior's amplitude (the prior check's bound scales it: next test)
    res = res.replace(uncertainty=dataclasses.replace(res.uncertainty, prior_check={}))
    pred = res.predict(far, model)
    assert pred.field_amplitude == 1.0 and "stated prior's amplitude (the prior check not run)" in pred.representation
    ev = model.evaluate(res.estimate.p_hat, far)
    alpha, eta = model.correction_field().seen(ev)
    assert np.min(alpha[eta > 0.35]) > 8.0 + 4.0            # every outboard section beyond the last hat
    assert "include the field between and beyond" in pred.representation
    without = res.replace(uncertainty=dataclasses.replace(res.uncertainty, gain=np.zeros((0, 0)))).predict(far, model)
    assert np.all(without.std[0] < 0.2 * pred.std[0])       # the nodes alone say the nominal polar is exact there

    # Monte Carlo: fields drawn from the prior on the fine grid, through the nonlinear model
    field = model.correction_field()
    fine = refined_grid(field.grid, np.concatenate([alpha, res.fit.alpha_seen]),
                        np.concatenate([eta, res.fit.eta_seen]))
    fmodel = model.with_grid(fine)
    flay = fmodel.correction_field().layout
    T = interpolation_matrix(field.grid, fine)
    D = discrepancy_correlation(field.grid, fine,
                                field.between_node_lengths(res.provenance.settings["prior_correlation"]))
    w, Q = np.linalg.eigh(D)
    root = Q * np.sqrt(np.clip(w, 0.0, None))
    lay = field.layout
    base = nominal_vector(fmodel.parameters)
    sd = [float(np.sqrt(np.mean(res.uncertainty.prior_std[idx.ravel()] ** 2))) for idx in (lay.lift_index,
                                                                                           lay.drag_index)]
    rng = np.random.default_rng(20261126)
    outs = []
    for _ in range(160):
        p = base.copy()
        for k, (f_idx, c_idx) in enumerate(((flay.lift_index, lay.lift_index), (flay.drag_index, lay.drag_index))):
            p[f_idx.ravel()] = T @ res.estimate.p_hat[c_idx.ravel()] + sd[k] * root @ rng.standard_normal(root.shape[1])
        p = np.clip(p, [q.lower for q in fmodel.parameters], [q.upper for q in fmodel.parameters])
        e = fmodel.evaluate(p, far)
        if e.ok[0]:
            outs.append(e.values[0, :len(CHANNELS)])
    outs = np.array(outs)
    assert len(outs) >= 150
    mc_var = outs.var(axis=0, ddof=1)
    ratio = pred.std[0] ** 2 / mc_var
    print("ratio", ratio, pred.std[0], np.sqrt(mc_var), without.std[0], np.min(alpha[eta > 0.35]))
    # 160 draws: the sample variance is within ±25 % of the true one at about 2.3σ; the
    # linearization at p̂ is what is being checked, so allow that band around 1
    assert np.all((ratio > 0.6) & (ratio < 1.6)), (ratio, pred.std[0], np.sqrt(mc_var))


def test_the_field_beyond_the_nodes_is_carried_at_the_prior_check_s_upper_bound(calibrated):
    """The field's part of the variance is the stated prior's times the square of the largest amplitude the
    data allow (calib.calibration.prediction.field_amplitude); the rest of the variance is unchanged."""
    model, res, far = calibrated
    pc = res.uncertainty.prior_check
    assert pc and np.isfinite(pc["upper"]) and pc["upper"] < 1.0        # data made with no field: "smaller"
    stated = res.replace(uncertainty=dataclasses.replace(res.uncertainty, prior_check={})).predict(far, model)
    for upper, expect in ((pc["upper"], pc["upper"]), (3.0, 3.0), (np.inf, 10.0), (40.0, 10.0)):
        r = res.replace(uncertainty=dataclasses.replace(res.uncertainty, prior_check={**pc, "upper": upper}))
        pred = r.predict(far, model)
        assert pred.field_amplitude == expect
        np.testing.assert_allclose(pred.field_std, expect * stated.field_std, rtol=1e-10)
        np.testing.assert_allclose(pred.std ** 2 - pred.field_std ** 2, stated.std ** 2 - stated.field_std ** 2,
                                   rtol=1e-8, atol=1e-12 * np.max(stated.std ** 2))
    assert "do not bound it" in pred.representation
    # inside the calibration envelope (the calibration's own points) the stated prior's amplitude stays
    cal = OperatingConditions(**res.conditions)
    at_cal = r.predict(cal, model)
    assert not at_cal.outside.any()
    np.testing.assert_allclose(at_cal.field_std, stated_cal := res.replace(uncertainty=dataclasses.replace(
        res.uncertainty, prior_check={})).predict(cal, model).field_std, rtol=1e-10)
    assert np.max(stated_cal) > 0
    failed = res.replace(uncertainty=dataclasses.replace(res.uncertainty, prior_check={"failed": "singular"}))
    assert failed.predict(far, model).field_amplitude == 1.0


def test_a_result_without_gain_says_its_bands_leave_the_field_out(calibrated):
    model, res, far = calibrated
    pred = res.replace(uncertainty=dataclasses.replace(res.uncertainty, gain=np.zeros((0, 0)))).predict(far, model)
    assert "leave out the field between and beyond" in pred.representation


def test_a_band_split_under_the_map_carries_each_fold_s_field_amplitude():
    """Each fold of a band split runs the prior check under the MAP (cheap: it linearizes at the estimate),
    and its rows record the field's part of the interval, the amplitude it was carried at and τ̂."""
    from calib.workflow.validation import ValidationSettings, leave_one_out

    rotor = load_rotor("phase_vi")
    grid = CorrectionGrid([-4.0, 4.0, 12.0], [0.3, 0.6, 1.0])

    def make():
        return BemModel(rotor, grid, CHANNELS, BemSettings(use_tilt=False), nuisance=())

    tsr, pitch = np.meshgrid([4.0, 5.0, 6.0, 7.0, 8.0, 9.0], [0.0, 3.0], indexing="ij")
    v = 72 * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, 72.0), pitch.ravel())
    meas = synthesize(make(), nominal_vector(make().parameters), cond,
                      relative_sigma={c: 0.01 for c in CHANNELS}, seed=12)
    band = ValidationSettings.from_table({"leave_out": "wind_speed", "split": "band"}, "cfg.toml")
    val = leave_one_out(make, meas, CalibrationSettings(cd_min=0.003), band)
    assert len(val.rows) == 2 * meas.n_points
    for r in val.rows:
        assert np.isfinite(r.prior_amplitude) and 0 < r.field_amplitude <= 10.0 and np.isfinite(r.field_std)
        assert r.field_std <= r.model_std * (1 + 1e-9)
    assert {round(r.field_amplitude, 12) for r in val.rows} != {1.0}      # the folds' own bounds, not the stated 1
    truncated = leave_one_out(make, meas, CalibrationSettings(cd_min=0.003, estimator="truncated"), band)
    assert all(np.isnan(r.prior_amplitude) for r in truncated.rows)      # no gain, no field term: no check run
