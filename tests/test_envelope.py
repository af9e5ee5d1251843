"""Each predicted point says whether it lies where the calibration's data were."""

import csv

import numpy as np

from calib.calibration import CalibrationSettings, Calibrator
from calib.envelope import envelope_of
from calib.measurements import synthesize
from calib.models.base import nominal_vector
from calib.predict import write_prediction_csv
from twin_model import RADIUS, TwinModel, twin_conditions


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
