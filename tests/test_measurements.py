"""Measurement tables: units, noise models and every bad-input path (file, row, column named)."""

import numpy as np
import pytest

from calib.calibration import CalibrationSettings, Calibrator
from calib.errors import InputError
from calib.measurements import Measurements, ml_noise, noise_from_repeats, read_measurements, synthesize
from calib.models.base import OperatingConditions, nominal_vector
from twin_model import TwinModel, twin_conditions

GOOD = """# a comment line
wind_speed,rotor_speed [rad/s],pitch [deg],air_density,power [kW],thrust [kN],power_sigma [kW],thrust_sigma [kN],cn@0.30,cn@0.30_sigma
8.0,1.0,0.0,1.2,1500,300,15,3,1.1,0.02
10.0,1.2,2.0,1.2,2500,350,25,3.5,1.2,0.02
"""


def write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_units_are_converted_to_si(tmp_path):
    m = read_measurements(write(tmp_path, GOOD))
    assert m.channels == ("power", "thrust", "cn@0.30")
    np.testing.assert_allclose(m.channel("power"), [1.5e6, 2.5e6])
    np.testing.assert_allclose(m.channel("thrust"), [3.0e5, 3.5e5])
    np.testing.assert_allclose(m.conditions.rotor_speed, np.array([1.0, 1.2]) * 30 / np.pi)
    np.testing.assert_allclose(m.sigma[:, 0], [1.5e4, 2.5e4])
    assert len(m.sha256) == 64


def test_round_trip_through_write_csv(tmp_path):
    m = read_measurements(write(tmp_path, GOOD), ["power", "thrust"])
    back = read_measurements(m.write_csv(tmp_path / "again.csv"))
    np.testing.assert_allclose(back.values, m.values)
    np.testing.assert_allclose(back.sigma, m.sigma)


@pytest.mark.parametrize("text, line, field, words", [
    ("rotor_speed,pitch,power\n10,0,1\n", 1, "wind_speed", "missing required column"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,nan\n", 2, "power", "finite"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,\n", 2, "power", "not a number"),
    ("wind_speed,rotor_speed,pitch,power [hp]\n8,10,0,1\n", 1, "power", "unknown unit [hp]"),
    ("wind_speed,rotor_speed,pitch,power,power_sigma\n8,10,0,1,0\n", 2, "power_sigma", "sigma must be > 0"),
    ("wind_speed,rotor_speed,pitch,power,power_sigma\n8,10,0,1,-2\n", 2, "power_sigma", "sigma must be > 0"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0\n", 2, None, "cells"),
    ("wind_speed,rotor_speed,pitch,power\n", 1, None, "no data rows"),
])
def test_bad_csv_names_file_line_and_column(tmp_path, text, line, field, words):
    path = write(tmp_path, text)
    with pytest.raises(InputError) as err:
        read_measurements(path)
    msg = str(err.value)
    assert str(path) in msg and words in msg
    assert err.value.line == line
    if field is not None:
        assert err.value.field == field


def test_empty_file(tmp_path):
    path = write(tmp_path, "# only a comment\n\n")
    with pytest.raises(InputError, match="empty file") as err:
        read_measurements(path)
    assert str(path) in str(err.value)


def test_channel_the_model_does_not_provide(tmp_path):
    path = write(tmp_path, GOOD)
    meas = read_measurements(path)                      # has cn@0.30, the twin model has not
    model = TwinModel(channels=("power", "thrust"))
    with pytest.raises(InputError) as err:
        Calibrator(model, meas, CalibrationSettings())
    msg = str(err.value)
    assert "cn@0.30" in msg and "power, thrust" in msg and str(path) in msg


def test_requested_channel_absent_from_file(tmp_path):
    with pytest.raises(InputError, match="channel 'torque' is not in the file"):
        read_measurements(write(tmp_path, GOOD), ["power", "torque"])


def test_noise_from_repeated_records_and_ml():
    model = TwinModel()
    cond = twin_conditions()
    p = nominal_vector(model.parameters)
    meas = synthesize(model, p, cond, sigma={"power": 2000.0, "thrust": 50.0}, repeats=6, seed=4)
    est = noise_from_repeats(meas)
    # pooled estimate over 40 groups x 5 dof: within ~10 % of the truth
    np.testing.assert_allclose(est, [2000.0, 50.0], rtol=0.1)
    exact = model.evaluate(p, meas.conditions).values
    np.testing.assert_allclose(ml_noise(meas.values - exact), [2000.0, 50.0], rtol=0.1)
    with pytest.raises(InputError, match="repeated records"):
        noise_from_repeats(synthesize(model, p, cond, sigma={"power": 1.0, "thrust": 1.0}))


def test_unknown_noise_is_estimated_by_iterated_ml():
    model = TwinModel(channels=("power", "thrust", "root_flap_moment"))
    cond = twin_conditions()
    p = nominal_vector(model.parameters)
    p[3] = 0.05
    meas = synthesize(model, p, cond, relative_sigma={"power": 0.01, "thrust": 0.02, "root_flap_moment": 0.01},
                      seed=9)
    true_sigma = meas.sigma[0].copy()
    blind = Measurements(meas.conditions, meas.channels, meas.values, None, source="blind")
    res = Calibrator(model, blind, CalibrationSettings(noise="ml", cd_min=None)).run()
    # ML noise is biased low by the fitted degrees of freedom, sqrt(1 - n_ret/N) per channel
    np.testing.assert_allclose(res.noise_sigma, true_sigma, rtol=0.25)
    assert any(h.get("stage") == "noise" for h in res.history)
