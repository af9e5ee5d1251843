"""A pitch offset under a free correction field, and what would tighten its σ (calib.calibration.tightening).

The linear-Gaussian update of the covariance is checked against refitting with the suggested
measurements added: the σ the advice promises is the σ the calibration then states.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.tightening import candidate_groups, sentence
from calib.corrections import CorrectionGrid
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector

CHANNELS = ("power", "thrust")


@pytest.fixture(scope="module")
def offset_case():
    rotor = load_rotor("nrel5mw")
    grid = CorrectionGrid([-4.0, 2.0, 8.0, 14.0], [0.3, 0.6, 1.0])
    model = BemModel(rotor, grid, CHANNELS + ("root_flap_moment",), BemSettings(use_tilt=False),
                     nuisance=("pitch_offset",))
    tsr, pitch = np.meshgrid(np.linspace(6.0, 10.5, 6), [0.0, 2.0], indexing="ij")
    v = 11.0 * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, 11.0), pitch.ravel())
    p = nominal_vector(model.parameters)
    j = [q.name for q in model.parameters].index("pitch_offset")
    p[j] = 1.5
    meas = synthesize(model, p, cond, relative_sigma={c: 0.01 for c in CHANNELS}, channels=CHANNELS, seed=7040)
    res = Calibrator(model, meas, CalibrationSettings(cd_min=0.003)).run()
    return model, meas, res, j, rotor


def test_a_pitch_offset_under_a_free_field_is_recovered_and_the_advice_names_what_tightens_it(offset_case):
    model, meas, res, j, _ = offset_case
    assert res.provenance.settings["estimator"] == "map" and res.estimate.status == "converged", res.estimate.message
    assert abs(res.estimate.p_hat[j] - 1.5) < 3 * res.uncertainty.std_p[j], (res.estimate.p_hat[j], res.uncertainty.std_p[j])
    advice = res.identifiability.tightening["pitch_offset"]
    assert advice["sigma"] == pytest.approx(res.uncertainty.std_p[j], rel=1e-9)
    assert advice["groups"] and all(g["ratio"] < 0.95 for g in advice["groups"])
    words = sentence("pitch_offset", advice, "deg")
    assert words.startswith("To tighten pitch_offset's σ, measure ") and "deg" in words
    print(words)


def test_the_promised_sigma_is_what_a_refit_with_those_measurements_states(offset_case):
    """Add the best group's points (noise-free, at the campaign's relative noise) and refit: the
    refit's σ of the pitch offset is the advice's, within what the re-linearization moves."""
    model, meas, res, j, rotor = offset_case
    best = res.identifiability.tightening["pitch_offset"]["groups"][0]
    groups = {what: (cond, chans) for what, cond, chans in
              candidate_groups(meas.conditions, rotor.rotor_radius, [c.name for c in model.channels],
                               list(meas.channels))}
    cond, chans = groups[best["what"]]
    if list(chans) != list(meas.channels):
        pytest.skip(f"best group is another channel ({best['what']}): not refittable with this campaign's table")
    # the noise the advice assumes: the campaign's median relative σ on max(|y|, 0.1 max|y|)
    rel = np.median(res.fit.sigma / np.abs(res.fit.model_after), axis=0)
    y = model.evaluate(res.estimate.p_hat, cond).values[:, :2]
    both = dataclasses.replace(
        meas, conditions=OperatingConditions(*(np.concatenate([getattr(meas.conditions, f), getattr(cond, f)])
                                               for f in ("wind_speed", "rotor_speed", "pitch", "air_density", "yaw"))),
        values=np.vstack([meas.values, y]),
        sigma=np.vstack([meas.sigma, rel * np.maximum(np.abs(y), 0.1 * np.abs(y).max(axis=0))]))
    refit = Calibrator(model, both, CalibrationSettings(cd_min=0.003, tightening=False)).run()
    print(f"promised σ {best['sigma']:.3g}, refit σ {refit.uncertainty.std_p[j]:.3g} deg ({best['what']})")
    assert refit.uncertainty.std_p[j] == pytest.approx(best["sigma"], rel=0.25), (refit.uncertainty.std_p[j], best)
    assert refit.uncertainty.std_p[j] < 0.9 * res.uncertainty.std_p[j]
