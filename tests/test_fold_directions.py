"""Retained θ that a point with several roots of the BEM equations determines.

Near a fold of the BEM residual the kept root's sensitivity grows without bound, and a
direction that such a point alone determines gets a σ that holds only on a narrow ridge
(coverage twin (d), tuning seed 8301: 99.5 % of the leading direction from one point, the
estimate 8.9 σ from the truth along it). Such a direction is stated with its prior variance
added, and the result and report say so (``calib.calibration.fold_directions.fold_dominated_directions``).
"""

import dataclasses

import numpy as np
from test_calibration import CHANNELS, twin_truth
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.fold_directions import FOLD_SHARE, fold_dominated_directions
from calib.calibration.result import fold_sentence
from calib.calibration.result_files import load_result
from calib.measurements import Measurements, synthesize
from calib.report.html import result_section


def _sensitivities(n_points=8, n_channels=2, n_params=4, loud=None, gain=100.0, seed=3):
    M = np.random.default_rng(seed).standard_normal((n_points * n_channels, n_params))
    if loud is not None:
        M[loud * n_channels:(loud + 1) * n_channels] *= gain
    _, s, Vt = np.linalg.svd(M, full_matrices=False)
    return M, s, Vt.T


def test_a_flagged_point_that_carries_a_direction_is_reported_with_its_share_and_sensitivity():
    M, s, V = _sensitivities(loud=2)
    flagged = np.zeros(8, bool)
    flagged[2] = True
    out = fold_dominated_directions(M, 2, V[:, :3], s[:3], flagged)
    # its two channels' rows, 100 times the others, carry the two leading directions
    assert [d["theta"] for d in out] == [1, 2] and {d["point"] for d in out} == {2}
    u = M @ V[:, 0] / s[0]
    assert np.isclose(out[0]["share"], np.sum(u[4:6] ** 2), rtol=1e-12) and out[0]["share"] > 0.99
    norms = np.linalg.norm(M.reshape(8, 2, 4), axis=(1, 2))
    assert np.isclose(out[0]["sensitivity_ratio"], norms[2] / np.median(np.delete(norms, 2)))


def test_no_report_without_a_flag_for_an_ordinary_flagged_point_or_for_a_left_out_point():
    M, s, V = _sensitivities(loud=2)
    assert fold_dominated_directions(M, 2, V[:, :3], s[:3], np.zeros(8, bool)) == []
    ordinary = np.zeros(8, bool)
    ordinary[5] = True                      # a point with several roots that dominates nothing
    assert fold_dominated_directions(M, 2, V[:, :3], s[:3], ordinary) == []
    flagged = np.zeros(8, bool)
    flagged[2] = True
    ok = np.ones(8, bool)
    ok[2] = False                           # a failed point takes no part
    assert fold_dominated_directions(M, 2, V[:, :3], s[:3], flagged, ok) == []
    assert fold_dominated_directions(M, 2, V[:, :0], s[:0], flagged) == []


def test_the_share_threshold_is_a_strict_majority_of_the_information():
    M, s, V = _sensitivities(loud=2, gain=1.0)
    u = M @ V / s
    energy = (u ** 2).reshape(8, 2, -1).sum(axis=1)
    j, i = np.unravel_index(np.argmax(energy[:, :3]), energy[:, :3].shape)
    flagged = np.zeros(8, bool)
    flagged[j] = True
    below = fold_dominated_directions(M, 2, V[:, :3], s[:3], flagged, share=energy[j, i] + 1e-9)
    at = fold_dominated_directions(M, 2, V[:, :3], s[:3], flagged, share=energy[j, i] - 1e-9)
    assert below == [] and (int(j), int(i) + 1) in [(d["point"], d["theta"]) for d in at]
    assert FOLD_SHARE == 0.5


class _FoldTwin(TwinModel):
    """The analytic twin, reporting several roots at the points in ``flagged``."""

    def __init__(self, flagged=(), **kw):
        super().__init__(**kw)
        self.flagged = tuple(flagged)

    def evaluate(self, p, conditions):
        ev = super().evaluate(p, conditions)
        mr = np.zeros(len(conditions), bool)
        mr[list(self.flagged)] = True
        return dataclasses.replace(ev, extras={**ev.extras, "multiple_roots": mr})


def _calibrate(flagged, tmp_path=None):
    """A twin whose first point is measured 300 times more precisely than the others, so that
    it alone determines the leading direction; ``flagged`` the points reported with several
    roots."""
    model = _FoldTwin(flagged, channels=CHANNELS)
    cond = twin_conditions(tsr=np.linspace(4.0, 10.0, 4))
    truth = twin_truth(model)
    meas = synthesize(model, truth, cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=7130)
    values, sigma = meas.values.copy(), meas.sigma.copy()
    values[0] = model.evaluate(truth, cond).values[0]
    sigma[0] /= 300.0
    meas = Measurements(meas.conditions, meas.channels, values, sigma, "fold twin")
    return Calibrator(model, meas, CalibrationSettings(estimator="truncated", cd_min=None, sigma_bar=1.0,
                                                       prior_check=False,
                                                      curvature_samples=0)).run()


def test_a_direction_a_flagged_point_determines_is_stated_with_at_least_its_prior_variance(tmp_path):
    plain, fold = _calibrate(()), _calibrate((0,))
    assert plain.identifiability.fold_directions == []
    # the point carries the leading direction (and others: its three channels' rows hold at most
    # 3 units of information, so at most 5 directions can take more than half of theirs from it)
    assert {d["point"] for d in fold.identifiability.fold_directions} == {0}
    thetas = sorted(d["theta"] for d in fold.identifiability.fold_directions)
    assert thetas[0] == 1 and len(thetas) <= 5
    first = next(d for d in fold.identifiability.fold_directions if d["theta"] == 1)
    v = fold.identifiability.V[:, 0]
    prior_var = float(v @ np.diag((fold.uncertainty.prior_std / fold.estimate.scale) ** 2) @ v)

    def sd_along(res):
        return float(np.sqrt(v @ (res.uncertainty.cov_p / np.outer(res.estimate.scale, res.estimate.scale)) @ v))
    # the same estimate; along θ1 the stated σ goes from the noise's to at least the prior's
    assert np.allclose(fold.estimate.p_hat, plain.estimate.p_hat)
    assert sd_along(plain) < 0.1 * np.sqrt(prior_var) <= sd_along(fold)
    assert np.isclose(first["sigma_after"], sd_along(fold), rtol=1e-9)
    assert np.isclose(first["sigma_before"], sd_along(plain), rtol=1e-9)
    # said in the summary and the report, and kept through save and load
    assert "θ1 takes" in fold.summary() and "point 1 (" in fold.summary()
    assert "θ1 takes" in result_section(fold) and "θ1 takes" not in result_section(plain)
    fold.save(tmp_path)
    assert load_result(tmp_path).identifiability.fold_directions == fold.identifiability.fold_directions


def test_the_sentence_names_the_point_its_share_and_the_sigma_it_was_stated_with():
    rec = [{"point": 4, "theta": 2, "share": 0.995, "sensitivity_ratio": 83.8, "sigma_before": 0.21,
            "sigma_after": 2.3}]
    cond = {"wind_speed": np.arange(6.0), "pitch": np.full(6, -2.0), "rotor_speed": np.full(6, 72.0)}
    text = fold_sentence(rec, cond, tsr=np.full(6, 2.0))
    assert "θ2 takes 100 % of its information from point 5 (4 m/s, λ 2, pitch -2°)" in text
    assert "83.8× the median point's" in text and "0.21 → 2.3 scale units" in text
    assert "pull the rest of the fit" in text
    assert "point 5" in fold_sentence([{k: v for k, v in rec[0].items() if not k.startswith("sigma")}])
