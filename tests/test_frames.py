"""pandas in (calib.measurements.read_dataframe) and out (calib.calibration.frames): the same checks as the CSV reader, results as DataFrames."""

from __future__ import annotations

import numpy as np
import pytest
from floats import assert_same_numbers

from calib.errors import InputError
from calib.measurements import Measurements, read_dataframe, read_measurements

pd = pytest.importorskip("pandas")

TABLE = {"wind_speed": [6.0, 8.0, 10.0], "rotor_speed": [8.0, 9.5, 11.5], "pitch": [0.0, 0.0, 1.5],
         "power": [800.0, 1900.0, 3600.0], "thrust": [200.0, 330.0, 480.0]}


def test_a_dataframe_reads_as_the_same_table_in_a_csv_file(tmp_path):
    df = pd.DataFrame(TABLE)
    m = read_dataframe(df, units={"power": "kW", "thrust": "kN"})
    path = tmp_path / "t.csv"
    pd.DataFrame(TABLE).rename(columns={"power": "power [kW]", "thrust": "thrust [kN]"}).to_csv(path, index=False)
    ref = read_measurements(path)
    assert m.channels == ref.channels == ("power", "thrust")
    assert_same_numbers(m.values, ref.values)
    assert_same_numbers(m.values[:, 0], np.array(TABLE["power"]) * 1e3)     # kW -> W
    assert_same_numbers(m.conditions.pitch, ref.conditions.pitch)
    assert m.source == "DataFrame"
    # units in the column names work too, and give the same numbers
    named = read_dataframe(df.rename(columns={"power": "power [kW]", "thrust": "thrust [kN]"}))
    assert_same_numbers(named.values, m.values)


@pytest.mark.parametrize("change, words", [
    (lambda df: df.drop(columns="pitch"), "pitch"),
    (lambda df: df.assign(power=[800.0, np.nan, 3600.0]), "row 1 .by position, from 0.: missing value"),
    (lambda df: df.assign(power=["800", "x", "3600"]), "row 1 .by position, from 0.: .*'x'"),
])
def test_bad_dataframes_are_refused_naming_row_and_column(change, words):
    with pytest.raises(InputError, match=words):
        read_dataframe(change(pd.DataFrame(TABLE)), units={"power": "kW", "thrust": "kN"})


def test_a_unit_stated_twice_or_for_a_missing_column_is_refused():
    df = pd.DataFrame(TABLE).rename(columns={"power": "power [kW]"})
    with pytest.raises(InputError, match="states its unit in its name and in units="):
        read_dataframe(df, units={"power [kW]": "kW"})
    with pytest.raises(InputError, match="not in the DataFrame: torque"):
        read_dataframe(pd.DataFrame(TABLE), units={"torque": "kN m"})


def test_results_and_predictions_as_dataframes():
    from calib.bem import BemSettings
    from calib.calibration import CalibrationSettings, Calibrator
    from calib.corrections import CorrectionGrid
    from calib.measurements import synthesize
    from calib.models.bem_model import BemModel
    from calib.rotor.library import load_rotor
    from calib.types import OperatingConditions, nominal_vector

    rotor = load_rotor("nrel5mw")
    model = BemModel(rotor, CorrectionGrid([-4.0, 4.0, 12.0], [0.4, 1.0]), ("power", "thrust"),
                     BemSettings(use_tilt=False), ("pitch_offset",))
    tsr = np.linspace(5.0, 10.0, 6)
    v = 10.0 * np.pi / 30 * rotor.rotor_radius / tsr
    cond = OperatingConditions(v, np.full(v.size, 10.0), np.zeros(v.size))
    meas = synthesize(model, nominal_vector(model.parameters), cond, relative_sigma={"power": 0.01, "thrust": 0.01},
                      seed=3)
    res = Calibrator(model, meas, CalibrationSettings(prior_check=False, tightening=False)).run()
    params = res.parameters_frame()
    assert list(params.index) == [q.name for q in model.parameters]
    assert params.loc["pitch_offset", "unit"] == "deg" and params.loc["pitch_offset", "kind"] == "nuisance"
    # the frame holds the result's own arrays (a copy, no arithmetic): equal bit for bit
    np.testing.assert_array_equal(params["value"].to_numpy(), res.estimate.p_hat)
    np.testing.assert_array_equal(params["std"].to_numpy(), res.uncertainty.std_p)
    points = res.points_frame()
    assert len(points) == 6 and "power_calibrated [W]" in points and "tip_speed_ratio [-]" in points
    np.testing.assert_allclose(points["tip_speed_ratio [-]"], tsr, rtol=1e-12)
    np.testing.assert_array_equal(points["thrust [N]"], meas.values[:, 1])
    pred = res.predict(cond, model)
    frame = pred.to_dataframe(cond)
    np.testing.assert_array_equal(frame["power [W]"], pred.values[:, 0])
    np.testing.assert_array_equal(frame["thrust_upper [N]"], pred.upper[:, 1])
    assert set(frame["status"]) == {"CONVERGED"} and set(frame["envelope"]) == {"inside"}
    np.testing.assert_array_equal(frame["wind_speed [m/s]"], v)


def test_rows_dropped_from_a_dataframe_are_named_by_their_position():
    """read_dataframe(drop_incomplete_rows=True) is in its signature, and its note names the DataFrame's
    rows by position, as its errors do (it said "lines 7" for row 5; issue 35)."""
    import inspect

    df = pd.DataFrame(TABLE)
    df.loc[1, "power"] = float("nan")
    assert "drop_incomplete_rows" in inspect.signature(read_dataframe).parameters
    m = read_dataframe(df, units={"power": "kW", "thrust": "kN"}, drop_incomplete_rows=True)
    assert m.n_points == len(df) - 1
    assert any("(rows 1, by position from 0)" in n for n in m.notes), m.notes


def test_the_old_constructor_says_the_new_name():
    with pytest.raises(InputError, match=r"calib\.measurements\.read_dataframe\(df, \.\.\.\)"):
        Measurements.from_dataframe(pd.DataFrame(TABLE), units={"power": "kW", "thrust": "kN"})
