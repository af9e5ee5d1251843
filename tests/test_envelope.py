"""Each predicted point says whether it lies where the calibration's data were."""

import csv

import numpy as np
from twin_model import RADIUS, TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.predict_command import write_prediction_csv
from calib.checks.envelope import envelope_of
from calib.measurements import synthesize
from calib.types import nominal_vector


def test_envelope_names_what_lies_outside():
    cal = {"wind_speed": np.array([6.0, 9.0]), "rotor_speed": np.array([6.0, 9.0]) * 7 / RADIUS * 30 / np.pi,
           "pitch": np.array([0.0, 2.0])}
    lam = np.array([7.0, 10.0, 7.0])
    v = np.array([7.0, 7.0, 12.0])
    new = {"wind_speed": v, "rotor_speed": lam * v / RADIUS * 30 / np.pi, "pitch": np.array([1.0, -1.0, 1.0])}
    seen_a, seen_e = np.array([2.0, 8.0, 4.0, 12.0]), np.array([0.5, 0.5, 0.9, 0.9])
    alpha = np.array([[5.0, 11.0], [1.6, 12.6], [5.0, np.nan]])      # 1.6: inside by the 0.5 deg margin
    out = envelope_of(cal, RADIUS, new, alpha, np.array([0.5, 0.9]), seen_a, seen_e)
    assert out[0] == ""
    assert out[1] == ("λ 10 above 7; pitch -1 deg below 0 deg; 1 of 2 stations at α outside the calibrated range "
                      "(r/R 0.90: α 12.6 deg, calibrated 4 to 12 deg)")
    assert out[2] == "wind speed 12 m/s above 9 m/s"                        # an unloaded station is not judged
    assert envelope_of(cal, None, new)[1] == "pitch -1 deg below 0 deg"    # no radius: no λ check


def test_a_calibrated_twin_flags_its_extrapolations_in_the_prediction_and_the_csv(tmp_path):
    model = TwinModel(channels=("power", "thrust"))
    p_true = nominal_vector(model.parameters)
    cond = twin_conditions(tsr=(4.0, 5.5, 7.0))
    meas = synthesize(model, p_true, cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=9811)
    res = Calibrator(model, meas, CalibrationSettings(sigma_bar=0.3), name="twin").run()
    inside = res.predict(cond, model=model)
    assert not inside.outside.any(), [e for e in inside.envelope if e]
    beyond = twin_conditions(tsr=(7.0, 10.0), pitch=(0.0,), wind=(6.0,))
    pred = res.predict(beyond, model=model)
    # the twin has no rotor radius, so no λ range: its sections meet angles the calibration never reached
    assert pred.outside.tolist() == [False, True] and "stations at α outside the calibrated range" in pred.envelope[1]
    path = write_prediction_csv(tmp_path / "p.csv", beyond.as_dict(), pred, {})
    rows = list(csv.reader(path.open()))[1:]
    assert rows[0][-2:] == ["envelope", "outside_because"]
    assert [r[-2] for r in rows[1:]] == ["inside", "outside"] and rows[2][-1] == pred.envelope[1]


def test_a_band_split_calibrates_on_one_band_and_predicts_the_other_with_the_nominal_beside_it():
    import pytest

    from calib.errors import InputError
    from calib.workflow.validation import ValidationSettings, leave_one_out
    model = TwinModel(channels=("power", "thrust"))
    p_true = nominal_vector(model.parameters)
    p_true[:model.grid.n_lift] = 0.05 * np.sin(np.arange(model.grid.n_lift))
    cond = twin_conditions(tsr=(4.0, 5.5, 7.0), pitch=(0.0, 2.0), wind=(5.0, 7.0, 9.0, 11.0))
    meas = synthesize(model, p_true, cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=9812)
    band = ValidationSettings.from_table({"leave_out": "wind_speed", "split": "band"}, "cfg.toml")
    val = leave_one_out(lambda: TwinModel(channels=("power", "thrust")), meas, CalibrationSettings(sigma_bar=0.3),
                        band)
    assert sorted({r.fold for r in val.rows}) == ["calibrated at wind speed <= 7, predicting above",
                                                  "calibrated at wind speed > 7, predicting at or below"]
    assert len(val.rows) == 2 * meas.n_points                     # every point held back once, per channel
    above = [r for r in val.rows if r.group > 7]
    assert all(r.fold.endswith("predicting above") and r.outside.startswith("wind speed") for r in above)
    s = val.summary("power")
    assert s["folds"] == meas.n_points and s["outside_envelope"] == meas.n_points
    assert np.isfinite(s["chi2_per_point_calibrated"]) and np.isfinite(s["chi2_per_point_nominal"])
    assert "calibrated on one band of wind speed" in val.sentence("power")
    at9 = leave_one_out(lambda: TwinModel(channels=("power", "thrust")), meas, CalibrationSettings(sigma_bar=0.3),
                        ValidationSettings.from_table({"split": "band", "band_at": 9.0}, "cfg.toml"))
    assert {r.group for r in at9.rows if r.fold.endswith("predicting above")} == {11.0}
    for table, key in (({"split": "bands"}, "validation.split"), ({"split": "band", "leave_out": "point"},
                                                                   "validation.leave_out"),
                       ({"band_at": 5.0}, "validation.band_at")):
        with pytest.raises(InputError, match=key.replace(".", r"\.")):
            ValidationSettings.from_table(table, "cfg.toml")
    with pytest.raises(InputError, match="leaves one band empty"):
        ValidationSettings.from_table({"split": "band", "band_at": 11.0}, "cfg.toml").folds(
            np.array([5.0, 7.0, 11.0]), "data.csv")
