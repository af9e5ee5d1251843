"""Stated noise models (calib.calibration.noise, noise = "relative" / "relative_ml") and the workflow's
[diagnosis] / [validation] tables (calib.workflow.validation)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.noise import ml_scale, relative_noise
from calib.corrections import CorrectionGrid
from calib.diagnosis.in_workflow import diagnosis_settings
from calib.errors import InputError
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions
from calib.workflow.validation import ValidationSettings, leave_one_out


def test_relative_noise_is_a_fraction_of_each_channels_rms_with_groups():
    values = np.array([[3.0, 0.1, -0.2], [4.0, -0.1, 0.2]])
    sig = relative_noise(values, ["torque", "ct@0.30", "ct@0.95"], {"torque": 0.1, "ct": 0.5, "ct@0.95": 1.0})
    assert np.allclose(sig[:, 0], 0.1 * np.sqrt(12.5))
    assert np.allclose(sig[:, 1], 0.5 * 0.1)          # the group's fraction
    assert np.allclose(sig[:, 2], 1.0 * 0.2)          # the channel's own entry wins
    with pytest.raises(InputError, match="no relative noise for channel 'thrust'") as info:
        relative_noise(values[:, :1], ["thrust"], {"torque": 0.1}, "wf.toml")
    assert info.value.field == "calibration.relative_sigma.thrust"
    with pytest.raises(InputError, match="zero everywhere"):
        relative_noise(np.zeros((2, 1)), ["torque"], {"torque": 0.1})


def test_relative_settings_are_checked_with_their_key():
    with pytest.raises(InputError, match="needs relative_sigma") as info:
        CalibrationSettings(noise="relative").validate("wf.toml", "calibration.")
    assert info.value.field == "calibration.relative_sigma"
    with pytest.raises(InputError) as info:
        CalibrationSettings(noise="relative_ml", relative_sigma={"cn": -0.1}).validate("wf.toml", "calibration.")
    assert info.value.field == "calibration.relative_sigma.cn"
    assert ml_scale(40.0, 12, 2) == pytest.approx(2.0)


@pytest.fixture(scope="module")
def twin():
    """Phase VI hub loads from a known model, noise 2 % of the RMS; the stated model says 0.5 %."""
    rotor = load_rotor("phase_vi")
    grid = CorrectionGrid([0.0, 8.0, 16.0], [0.4, 0.7, 1.0])
    model = BemModel(rotor, grid, ["torque", "thrust"], None, ())
    cond = OperatingConditions(np.arange(6.0, 16.0, 1.0), np.full(10, 72.0), np.full(10, 3.0))
    p = np.array([q.nominal for q in model.parameters])
    clean = model.evaluate(p, cond).values
    rms = np.sqrt(np.mean(clean ** 2, axis=0))
    meas = synthesize(model, p, cond, sigma={"torque": 0.02 * rms[0], "thrust": 0.02 * rms[1]},
                      channels=["torque", "thrust"], seed=4242)
    return model, dataclasses.replace(meas, sigma=None), rms


def test_relative_ml_finds_the_noise_level_the_stated_model_got_wrong(twin):
    model, meas, rms = twin
    st = CalibrationSettings(noise="relative_ml", relative_sigma={"torque": 0.005, "thrust": 0.005}, cd_min=None)
    res = Calibrator(model, meas, st).run()
    ratio = res.fit.sigma[0] / (0.02 * rms)
    assert np.all((ratio > 0.6) & (ratio < 1.5)), ratio     # 20 residuals: k̂ within about ±35 % of the truth
    assert res.chi2_per_dof_after == pytest.approx(1.0, abs=0.05)
    fixed = Calibrator(model, meas, CalibrationSettings(noise="relative", relative_sigma={"torque": 0.005,
                                                                                         "thrust": 0.005},
                                                        cd_min=None)).run()
    assert fixed.chi2_per_dof_after > 5            # the stated 0.5 % taken as the truth: a misfit


def test_leave_one_out_counts_and_predicts_every_fold(twin):
    model, meas, _ = twin
    keep = np.arange(0, meas.n_points, 2)           # 5 wind speeds, 5 folds
    meas = dataclasses.replace(meas, conditions=meas.conditions.subset(keep), values=meas.values[keep])
    st = CalibrationSettings(noise="relative_ml", relative_sigma={"torque": 0.01, "thrust": 0.01}, cd_min=None)
    val = leave_one_out(lambda: model, meas, st, ValidationSettings("wind_speed", ("torque",)))
    s = val.summary("torque")
    assert s["folds"] == 5 and s["failed"] == 0
    assert s["inside"] >= 4           # truth = nominal model: intervals of model + noise cover the data
    assert all(r.lower < r.predicted < r.upper and r.noise_std > 0 for r in val.rows)
    with pytest.raises(InputError, match="at least 3 distinct values"):
        leave_one_out(lambda: model, meas, st, ValidationSettings("pitch"))


def test_validation_and_diagnosis_tables_name_the_bad_key():
    with pytest.raises(InputError) as info:
        ValidationSettings.from_table({"leave_out": "rotor"}, "wf.toml")
    assert info.value.field == "validation.leave_out"
    with pytest.raises(InputError) as info:
        ValidationSettings.from_table({"folds": 3}, "wf.toml")
    assert info.value.field == "validation.folds"
    with pytest.raises(InputError) as info:
        diagnosis_settings({"candidates": ["stall"]}, "wf.toml")
    assert info.value.field == "diagnosis.candidates"
    with pytest.raises(InputError) as info:
        diagnosis_settings({"significance": 2.0}, "wf.toml")
    assert info.value.field == "diagnosis.significance"


def _workflow(tmp_path, edit: tuple):
    from pathlib import Path

    from calib.workflow import load_workflow

    root = Path(__file__).resolve().parents[1]
    text = (root / "workflows" / "phase_vi.toml").read_text().replace(
        'file = "data/phase_vi_sequence_H.csv"', f'file = "{root / "workflows" / "data" / "phase_vi_sequence_H.csv"}"')
    path = tmp_path / "wf.toml"
    path.write_text(text.replace(*edit))
    return load_workflow(path)


def test_workflow_diagnosis_and_validation_errors_name_the_key(tmp_path):
    # checked when the workflow is loaded, as every other table
    with pytest.raises(InputError) as info:
        _workflow(tmp_path, edit=("[validation]\n", "[validation]\nfold = 2\n"))
    assert info.value.field == "validation.fold" and "wf.toml" in str(info.value)
    with pytest.raises(InputError) as info:
        _workflow(tmp_path, edit=("[diagnosis]\n", "[diagnosis]\nmax_effects = -1\n"))
    assert info.value.field == "diagnosis.max_effects"
    with pytest.raises(InputError, match="native BEM only") as info:
        _workflow(tmp_path, edit=("[grid]\n", '[model]\nkind = "fmu"\nvariant = "A"\n\n[grid]\n'))
    assert info.value.field == "diagnosis"
