"""Measurement tables: units, noise models and every bad-input path (file, row, column named)."""

import os
from pathlib import Path

import numpy as np
import pytest
from twin_model import TwinModel, twin_conditions

from calib.calibration import CalibrationSettings, Calibrator
from calib.errors import InputError
from calib.measurements import Measurements, ml_noise, noise_from_repeats, read_measurements, synthesize
from calib.types import nominal_vector

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


def test_write_csv_puts_the_bytes_on_disk_before_the_rename(tmp_path, monkeypatch):
    """The temporary file is fsynced, complete, before ``os.replace`` makes it the file: a crash
    after the rename cannot leave an empty or half-written table."""
    import calib.measurements.data as mm  # where Measurements.write_csv lives

    m = read_measurements(write(tmp_path, GOOD), ["power", "thrust"])
    events = []
    real_fsync, real_replace = mm.os.fsync, mm.os.replace

    def fsync(fd):
        events.append(("fsync", os.fstat(fd).st_size))
        real_fsync(fd)

    def replace(src, dst):
        events.append(("replace", Path(src).stat().st_size))
        real_replace(src, dst)

    monkeypatch.setattr(mm.os, "fsync", fsync)
    monkeypatch.setattr(mm.os, "replace", replace)
    out = m.write_csv(tmp_path / "again.csv")
    assert [e[0] for e in events] == ["fsync", "replace"]
    assert events[0][1] == events[1][1] == out.stat().st_size > 0


@pytest.mark.parametrize("text, line, field, words", [
    ("rotor_speed,pitch,power\n10,0,1\n", 1, "wind_speed", "missing required column"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,nan\n", 2, "power", "finite"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,\n", 2, "power", "missing value (empty cell) in column 4"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,abc\n", 2, "power", "not a number: 'abc'"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,inf\n", 2, "power", "finite"),
    ("wind_speed,rotor_speed,pitch,power [hp]\n8,10,0,1\n", 1, "power", "unknown unit [hp]"),
    ("wind_speed,rotor_speed,pitch,power,power_sigma\n8,10,0,1,0\n", 2, "power_sigma", "sigma must be > 0"),
    ("wind_speed,rotor_speed,pitch,power,power_sigma\n8,10,0,1,-2\n", 2, "power_sigma", "sigma must be > 0"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0\n", 2, "power", "cells"),
    ("wind_speed,rotor_speed,pitch,power\n8,10,0,1,2\n", 2, None, "cells"),
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
    np.testing.assert_allclose(res.fit.noise_sigma, true_sigma, rtol=0.25)
    assert any(h.get("stage") == "noise" for h in res.estimate.history)


# ----------------------------------------------------------------------------- field exports
FIXTURES = Path(__file__).parent / "data" / "measurements"
SI = {"wind_speed": [6.0, 8.0, 10.0], "rotor_speed": [8.0, 9.5, 11.5], "pitch": [0.0, 0.0, 1.5],
      "power": [0.75e6, 1.8e6, 3.5e6], "thrust": [2.1e5, 3.4e5, 4.9e5]}


def assert_reference_table(m):
    """The fixture's three points, in SI units (every fixture holds the same numbers)."""
    assert m.channels == ("power", "thrust")
    for f in ("wind_speed", "rotor_speed", "pitch"):
        np.testing.assert_allclose(getattr(m.conditions, f), SI[f], rtol=1e-9, err_msg=f)
    np.testing.assert_allclose(m.channel("power"), SI["power"], rtol=1e-12)
    np.testing.assert_allclose(m.channel("thrust"), SI["thrust"], rtol=1e-12)


def test_utf8_byte_order_mark_is_removed():
    m = read_measurements(FIXTURES / "bom.csv")
    assert_reference_table(m)
    assert "encoding: UTF-8 with byte-order mark" in m.notes
    assert "delimiter: comma (detected)" in m.notes


def test_timestamp_and_id_columns_are_ignored_with_a_note():
    m = read_measurements(FIXTURES / "timestamp.csv")
    assert_reference_table(m)
    assert "ignored non-numeric column(s): timestamp, turbine_id" in m.notes


def test_openfast_style_header_name_underscore_bracket_unit():
    m = read_measurements(FIXTURES / "openfast_header.csv")   # Power_[kW], Rotor_Speed_[RPM]
    assert_reference_table(m)
    assert m.metadata["units"]["power"] == "kW" and m.metadata["units"]["rotor_speed"] == "rpm"
    note = [n for n in m.notes if n.startswith("ignored unrecognised numeric column(s)")]
    assert note and "GenPwr_[kW]" in note[0] and "power" in note[0]


def test_header_unit_in_parentheses_and_blanks_in_names():
    m = read_measurements(FIXTURES / "parenthesis_units.csv")  # "wind speed (m/s)", "rotor speed (rad/s)"
    assert_reference_table(m)
    assert m.metadata["units"]["rotor_speed"] == "rad/s"


def test_semicolon_delimiter_is_detected_and_said():
    m = read_measurements(FIXTURES / "semicolon.csv")
    assert_reference_table(m)
    assert "delimiter: semicolon (detected)" in m.notes
    assert not m.metadata["decimal_comma"]


def test_semicolon_with_decimal_comma():
    m = read_measurements(FIXTURES / "semicolon_decimal_comma.csv")   # 1,5 means 1.5
    assert_reference_table(m)
    assert "decimal comma: ',' read as the decimal separator" in m.notes


def test_decimal_comma_file_refuses_a_point_as_ambiguous(tmp_path):
    path = write(tmp_path, "wind_speed;rotor_speed;pitch;power\n8,5;10;0;1.500,5\n")
    with pytest.raises(InputError, match="thousands separator") as err:
        read_measurements(path)
    assert err.value.line == 2 and err.value.field == "power"


def test_tab_delimiter_is_detected():
    m = read_measurements(FIXTURES / "tab.tsv")
    assert_reference_table(m)
    assert "delimiter: tab (detected)" in m.notes


@pytest.mark.parametrize("name, words", [("image.csv", "PNG image"), ("workbook.csv", "zip archive"),
                                         ("latin1.csv", "not UTF-8 text: byte 0xb0")])
def test_binary_or_non_utf8_file_gives_the_package_error(name, words):
    path = FIXTURES / name
    with pytest.raises(InputError) as err:                 # never a raw UnicodeDecodeError
        read_measurements(path)
    assert not isinstance(err.value, UnicodeDecodeError)
    assert words in str(err.value) and str(path) in str(err.value)


def test_incomplete_row_is_refused_naming_line_and_column():
    path = FIXTURES / "incomplete.csv"
    with pytest.raises(InputError) as err:
        read_measurements(path)
    assert err.value.line == 4 and err.value.field == "thrust"
    msg = str(err.value)
    assert "column 5 'thrust [kN]'" in msg and "drop_incomplete_rows" in msg and str(path) in msg


def test_incomplete_rows_dropped_on_request_with_the_count():
    m = read_measurements(FIXTURES / "incomplete.csv", drop_incomplete_rows=True)
    assert_reference_table(m)
    assert m.metadata["lines"] == (3, 5, 7)
    assert "dropped 2 of 5 rows with a missing value in a needed column (lines 4, 6)" in m.notes


def test_missing_value_in_an_unneeded_column_is_not_a_reason_to_refuse(tmp_path):
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power,thrust\n8,10,0,1e6,\n9,10,0,1.2e6,3e5\n")
    m = read_measurements(path, ["power"])                 # thrust not needed
    np.testing.assert_allclose(m.channel("power"), [1e6, 1.2e6])
    with pytest.raises(InputError, match="missing value"):
        read_measurements(path)


def test_names_and_units_are_case_insensitive(tmp_path):
    path = write(tmp_path, "WIND_SPEED [M/S],Rotor_Speed [RAD/S],PITCH [DEG],POWER [MW],Root_Flap_Moment [kN-m]\n"
                           "8,1,2,1.5,4000\n")
    m = read_measurements(path)
    assert m.channels == ("power", "root_flap_moment")
    np.testing.assert_allclose(m.values, [[1.5e6, 4.0e6]])
    np.testing.assert_allclose(m.conditions.rotor_speed, [30 / np.pi])


def test_unit_inside_the_name_is_pointed_out(tmp_path):
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power_kw\n8,10,0,1\n")
    with pytest.raises(InputError, match=r"'power_kw' \(did you mean 'power'\?\)"):
        read_measurements(path)


def test_columns_without_unit_are_said_to_be_si(tmp_path):
    m = read_measurements(write(tmp_path, "wind_speed [m/s],rotor_speed,pitch [deg],power\n8,10,0,1e6\n"))
    assert "no unit in the header, SI assumed: rotor_speed [rpm], power [W]" in m.notes


def test_space_separated_file_is_refused_with_the_accepted_delimiters(tmp_path):
    path = write(tmp_path, "wind_speed rotor_speed pitch power\n8 10 0 1\n")
    with pytest.raises(InputError, match="comma, a semicolon or a tab") as err:
        read_measurements(path)
    assert err.value.line == 1


def test_notes_survive_select_channels_and_are_written_as_comments(tmp_path):
    m = read_measurements(FIXTURES / "timestamp.csv")
    sub = m.select_channels(["thrust"])
    assert sub.notes == m.notes
    out = sub.write_csv(tmp_path / "out.csv")
    text = out.read_text()
    assert "# note: ignored non-numeric column(s): timestamp, turbine_id" in text
    assert "thrust [N]" in text and "rotor_speed [rpm]" in text
    back = read_measurements(out)
    np.testing.assert_allclose(back.values, sub.values)
    assert not any("timestamp" in n for n in back.notes)  # fresh notes describe the written file


def test_utf16_unicode_text_export(tmp_path):
    """A spreadsheet's "Unicode text" export: UTF-16 with byte-order mark, tab-separated."""
    text = (FIXTURES / "tab.tsv").read_text(encoding="utf-8")
    path = tmp_path / "unicode.txt"
    path.write_bytes(text.encode("utf-16"))
    m = read_measurements(path)
    assert_reference_table(m)
    assert "encoding: UTF-16 with byte-order mark" in m.notes and "delimiter: tab (detected)" in m.notes


def test_trailing_delimiter_and_odd_headers_are_ignored_columns(tmp_path):
    """A spreadsheet's trailing empty column and a header that is not 'name [unit]' do not refuse the file."""
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power [kW],power (avg) [kW],\n8,10,0,1500,1490,\n")
    m = read_measurements(path)
    np.testing.assert_allclose(m.channel("power"), [1.5e6])
    assert any(n.startswith("ignored unrecognised numeric column(s): power (avg) [kW]") for n in m.notes)
    assert "ignored non-numeric column(s): <column 6>" in m.notes


def test_a_rotor_and_a_measurement_table_print_as_a_short_summary(tmp_path):
    """print(rotor) and print(meas) dumped hundreds of lines of arrays (issue 35): one line each."""
    from calib.rotor.library import load_rotor

    rotor = load_rotor("nrel5mw")
    text = repr(rotor)
    assert "\n" not in text and len(text) < 200 and "19 stations" in text and "3 blades" in text, text
    path = tmp_path / "m.csv"
    path.write_text("wind_speed,rotor_speed,pitch,power [kW],power_sigma [kW]\n8,9,0,1500,15\n10,11,0,2500,25\n")
    meas = read_measurements(path, ["power"])
    text = repr(meas)
    assert "\n" not in text and "2 points × 1 channels (power)" in text and "with σ" in text, text
