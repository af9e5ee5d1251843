"""Measurement tables as loggers and OpenFAST write them: a units row under the header, and
OpenFAST text output (``.out``) with its channel names, units row and time series."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calib.errors import InputError
from calib.measurements import Measurements, read_measurements


def write(tmp_path, text, name="m.csv"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# ----------------------------------------------------------------------------- units row
UNITS_ROW = """# logger export: units in a row of their own
timestamp,wind_speed,rotor_speed,pitch,power,thrust,torque,root_flap_moment,cn@0.30
-,(m/s),(rad/s),(deg),[kW],kN,(kN-m),(kN·m),(-)
2024-05-01 10:00,8.0,1.0,0.0,1500,300,1200,4500,1.1
2024-05-01 10:10,10.0,1.2,2.0,2500,350,2000,5200,1.2
"""


def test_units_row_is_read_and_converted_to_si(tmp_path):
    m = read_measurements(write(tmp_path, UNITS_ROW))
    assert m.channels == ("power", "thrust", "torque", "root_flap_moment", "cn@0.30")
    # by hand: 1500 kW = 1.5e6 W, 300 kN = 3.0e5 N, 1200 kN m = 1.2e6 N m, 1 rad/s = 9.5493 rpm
    np.testing.assert_allclose(m.channel("power"), [1.5e6, 2.5e6], rtol=1e-12)
    np.testing.assert_allclose(m.channel("thrust"), [3.0e5, 3.5e5], rtol=1e-12)
    np.testing.assert_allclose(m.channel("torque"), [1.2e6, 2.0e6], rtol=1e-12)
    np.testing.assert_allclose(m.channel("root_flap_moment"), [4.5e6, 5.2e6], rtol=1e-12)
    np.testing.assert_allclose(m.channel("cn@0.30"), [1.1, 1.2], rtol=1e-12)
    np.testing.assert_allclose(m.conditions.rotor_speed, [9.549296585513720, 11.459155902616464], rtol=1e-12)
    np.testing.assert_allclose(m.conditions.wind_speed, [8.0, 10.0], rtol=1e-12)
    assert m.metadata["units"]["power"] == "kW" and m.metadata["units"]["rotor_speed"] == "rad/s"
    assert m.metadata["units_row"] == 3 and m.metadata["lines"] == (4, 5)
    assert "units row on line 3" in m.notes
    assert "ignored non-numeric column(s): timestamp" in m.notes
    # a row of descriptions under the header is not a units row: the old message stands
    path = write(tmp_path, "wind_speed,rotor_speed,pitch,power\nWind speed at hub,Rotor speed,Pitch,Power\n8,9,0,1\n",
                 "described.csv")
    with pytest.raises(InputError, match="not a number: 'Wind speed at hub'") as err:
        read_measurements(path)
    assert (err.value.line, err.value.field) == (2, "wind_speed")


def test_units_row_in_a_tab_separated_logger_export_with_bare_units(tmp_path):
    text = ("Time\twind_speed\trotor_speed\tpitch\tpower\n"
            "s\tkm/h\trpm\tdeg\tMW\n"
            "0\t36\t12\t1.5\t2.5\n")
    m = read_measurements(write(tmp_path, text, "logger.tsv"))
    np.testing.assert_allclose(m.conditions.wind_speed, [10.0], rtol=1e-12)      # 36 km/h = 10 m/s
    np.testing.assert_allclose(m.channel("power"), [2.5e6], rtol=1e-12)          # 2.5 MW
    assert m.metadata["format"] == "csv" and m.metadata["units_row"] == 2


def test_unit_in_both_header_and_units_row_names_the_column(tmp_path):
    text = "wind_speed,rotor_speed,pitch,power [kW]\n(m/s),(rpm),(deg),(kW)\n8,9,0,1500\n"
    path = write(tmp_path, text)
    with pytest.raises(InputError) as err:
        read_measurements(path)
    msg = str(err.value)
    assert str(path) in msg and "column 4 'power [kW]'" in msg and "units row" in msg and "header" in msg
    assert (err.value.line, err.value.field) == (2, "power")


def test_unknown_unit_in_units_row_names_line_column_and_valid_units(tmp_path):
    text = "wind_speed,rotor_speed,pitch,power\n(m/sec),(rpm),(deg),(kW)\n8,9,0,1500\n"
    path = write(tmp_path, text)
    with pytest.raises(InputError) as err:
        read_measurements(path)
    msg = str(err.value)
    assert str(path) in msg and "unknown unit [m/sec] for speed" in msg and "column 1 'wind_speed'" in msg
    assert "accepted units: m/s, km/h" in msg
    assert (err.value.line, err.value.field) == (2, "wind_speed")


# ----------------------------------------------------------------------------- OpenFAST .out
OUT_CHANNELS = ["Time", "Wind1VelX", "Wind1VelY", "BldPitch1", "Azimuth", "RotSpeed", "RotThrust", "RotTorq",
                "RotPwr", "RootMxc1", "RootMyc1", "RootMyb1", "GenPwr"]
OUT_UNITS = ["(s)", "(m/s)", "(m/s)", "(deg)", "(deg)", "(rpm)", "(kN)", "(kN-m)", "(kW)", "(kN-m)", "(kN-m)",
             "(kN-m)", "(kW)"]
#: steady part (t >= 10 s): mean and the amplitude of an alternating +/- wiggle, per channel
STEADY = {"Wind1VelX": (11.4, 0.2), "Wind1VelY": (0.1, 0.3), "BldPitch1": (1.5, 0.1), "RotSpeed": (12.0, 0.05),
          "RotThrust": (700.0, 20.0), "RotTorq": (3950.0, 30.0), "RotPwr": (5000.0, 100.0),
          "RootMxc1": (2000.0, 1500.0), "RootMyc1": (9500.0, 300.0), "RootMyb1": (9000.0, 300.0),
          "GenPwr": (4800.0, 90.0)}


def openfast_text(delimiter="\t", n_transient=10, n_steady=10) -> str:
    """An OpenFAST text output as OpenFAST 3.5 writes it (ES10.3E2 numbers, padded names)."""
    lines = ["",
             "Predictions were generated on 05-May-2024 at 10:00:00 using OpenFAST, compiled as a 64-bit "
             "application using double precision at commit v3.5.0",
             " linked with  NWTC Subroutine Library; ElastoDyn; InflowWind; AeroDyn; ServoDyn",
             "",
             "Description from the FAST input file: NREL 5.0 MW Baseline Wind Turbine (Onshore)",
             "",
             delimiter.join(f"{c:<10}" for c in OUT_CHANNELS),
             delimiter.join(f"{u:<10}" for u in OUT_UNITS)]
    for k in range(n_transient + n_steady):
        t = float(k)
        row = [f"{t:10.4f}"]
        for c in OUT_CHANNELS[1:]:
            if c == "Azimuth":
                x = (t * 72.6) % 360.0
            elif k < n_transient:                    # start-up transient: far from the steady values
                x = 0.6 * STEADY[c][0]
            else:
                mean, amp = STEADY[c]
                x = mean + amp * (-1) ** k
            row.append(f"{x:10.3E}")
        lines.append(delimiter.join(row))
    return "\n".join(lines) + "\n"


def test_openfast_out_is_read_with_channel_mapping_and_averaged(tmp_path):
    path = write(tmp_path, openfast_text(), "5MW_Land.out")
    m = read_measurements(path, time_series="mean", average_from=10.0)
    assert m.n_points == 1
    assert m.channels == ("thrust", "torque", "power", "root_edge_moment", "root_flap_moment")   # file order
    # by hand: the steady rows alternate +/- around the mean, an even count, so the mean is exact;
    # kW -> W, kN -> N, kN-m -> N m
    np.testing.assert_allclose(m.conditions.wind_speed, [11.4], rtol=1e-9)
    np.testing.assert_allclose(m.conditions.rotor_speed, [12.0], rtol=1e-9)
    np.testing.assert_allclose(m.conditions.pitch, [1.5], rtol=1e-9)
    np.testing.assert_allclose(m.channel("power"), [5.0e6], rtol=1e-9)
    np.testing.assert_allclose(m.channel("thrust"), [7.0e5], rtol=1e-9)
    np.testing.assert_allclose(m.channel("torque"), [3.95e6], rtol=1e-9)
    np.testing.assert_allclose(m.channel("root_flap_moment"), [9.5e6], rtol=1e-9)   # RootMyc1, not RootMyb1
    np.testing.assert_allclose(m.channel("root_edge_moment"), [2.0e6], rtol=1e-9)   # RootMxc1
    assert m.metadata["format"] == "openfast"
    assert m.metadata["openfast_channels"]["root_flap_moment"] == "RootMyc1"
    assert m.metadata["time_window"] == (10.0, 19.0) and m.metadata["time_rows"] == 10
    notes = " | ".join(m.notes)
    assert "Wind1VelX -> wind_speed" in notes and "RotPwr -> power" in notes and "RootMyc1 -> root_flap_moment" in notes
    not_read = next(n for n in m.notes if n.startswith("OpenFAST channels not read"))
    for name in ("Wind1VelY", "Azimuth", "RootMyb1", "GenPwr"):
        assert name in not_read
    assert "Time" not in not_read                       # the time axis of the average
    assert "dropped the 10 time rows before average_from = 10 s" in notes
    # 9 s at 12.0 rpm (the +/- 0.05 wiggle cancels in each trapezoid) = 9 * 12 / 60 = 1.8 revolutions
    assert "10 rows, t = 10 to 19 s, 1.8 rotor revolutions" in notes
    assert "thrust is ElastoDyn's RotThrust" in notes


def test_openfast_time_series_is_refused_by_default_and_read_row_by_row_on_request(tmp_path):
    path = write(tmp_path, openfast_text(n_transient=0, n_steady=4), "run.out")
    with pytest.raises(InputError, match="OpenFAST time series .4 time rows, t = 0 to 3 s.*time_series='mean'") as err:
        read_measurements(path)
    assert err.value.line == 9 and str(path) in str(err.value)
    m = read_measurements(path, time_series="rows")
    assert m.n_points == 4 and m.metadata["lines"] == (9, 10, 11, 12)
    np.testing.assert_allclose(m.channel("power"), [5.1e6, 4.9e6, 5.1e6, 4.9e6], rtol=1e-9)


def test_openfast_space_separated_detected_from_content_with_aerodyn_loads_preferred(tmp_path):
    text = ("Predictions were generated on 05-May-2024 at 10:00:00 using OpenFAST\n\n"
            "Time  Wind1VelX  RotSpeed  BldPitch1  RotPwr  RtAeroPwr  RtAeroFxh  RootMyb1\n"
            "(s)   (m/s)      (rpm)     (deg)      (kW)    (W)        (N)        (kN-m)\n"
            "60.0  8.0        9.2       0.0        1.80E+03  1.85E+06  4.10E+05  7.00E+03\n")
    path = write(tmp_path, text, "steady_8mps.txt")
    m = read_measurements(path)
    assert m.channels == ("power", "thrust")
    np.testing.assert_allclose(m.channel("power"), [1.85e6], rtol=1e-12)           # RtAeroPwr (W), not RotPwr
    np.testing.assert_allclose(m.channel("thrust"), [4.10e5], rtol=1e-12)
    notes = " | ".join(m.notes)
    assert "RotPwr (power is read from RtAeroPwr)" in notes
    assert "RootMyb1 is a blade-axes moment that turns with pitch" in notes and "RootMyc1" in notes
    with pytest.raises(InputError, match="channel 'root_flap_moment' is not in the file; OpenFAST channel RootMyc1"):
        read_measurements(path, ["power", "root_flap_moment"])


def test_openfast_binary_output_is_refused(tmp_path):
    path = tmp_path / "run.outb"
    path.write_bytes(b"\x02\x00\x0d\x00\x00\x00" + bytes(range(256)) * 4)
    with pytest.raises(InputError, match=r"OpenFAST binary output \(\.outb\) is not read.*OutFileFmt") as err:
        read_measurements(path)
    assert str(path) in str(err.value)


# ----------------------------------------------------------------------------- fuzz
SEEDS = [UNITS_ROW.encode(), openfast_text(n_transient=2, n_steady=4).encode(),
         openfast_text(" ", n_transient=0, n_steady=3).encode()]


@st.composite
def mutated(draw):
    k = draw(st.integers(0, len(SEEDS) - 1))
    lines = SEEDS[k].split(b"\n")
    for _ in range(draw(st.integers(1, 4))):
        i = draw(st.integers(0, len(lines) - 1))
        action = draw(st.sampled_from(["delete", "duplicate", "garble", "token"]))
        if action == "delete" and len(lines) > 1:
            del lines[i]
        elif action == "duplicate":
            lines.insert(i, lines[i])
        elif action == "garble":
            lines[i] = draw(st.binary(max_size=40))
        else:
            tokens = lines[i].split(b"\t" if b"\t" in lines[i] else b",")
            j = draw(st.integers(0, len(tokens) - 1))
            tokens[j] = draw(st.sampled_from([b"", b"nan", b"1e308", b"(kW)", b"[kN]", b"(m/sec)", b"Time",
                                              b"(s)", b"-", b"x", b"1,5"]))
            lines[i] = (b"\t" if b"\t" in lines[i] else b",").join(tokens)
    return k, b"\n".join(lines)


@settings(max_examples=150, deadline=2000, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(case=mutated(), mode=st.sampled_from([None, "mean", "rows"]))
def test_fuzzed_units_rows_and_openfast_output_never_crash(tmp_path, case, mode):
    k, data = case
    path = tmp_path / ("m.csv" if k == 0 else "m.out")
    path.write_bytes(data)
    try:
        m = read_measurements(path, time_series=mode)
    except InputError as exc:
        assert exc.source == str(path)
        assert exc.line is not None or exc.field is not None or "file" in exc.message or "not a text" in exc.message
        return
    assert isinstance(m, Measurements) and m.n_points >= 1
    assert np.all(np.isfinite(m.values)) and np.all(m.conditions.wind_speed > 0)


def test_workflow_passes_the_time_series_options(tmp_path):
    """[measurements] time_series / average_from reach the reader; a bad value names the workflow key."""
    import dataclasses

    from calib.workflow import measurements_of, workflow_from_table

    write(tmp_path, openfast_text(), "5MW_Land.out")
    wf = workflow_from_table({"name": "t", "rotor": {"name": "nrel5mw"}, "stages": [{"name": "s", "channels": ["power"]}],
                              "grid": {"alpha_nodes_deg": "auto", "eta_nodes": [0.5, 1.0]},
                              "measurements": {"file": "5MW_Land.out", "time_series": "mean", "average_from": 10.0}},
                             "wf.toml", tmp_path)
    m = measurements_of(wf, ["power"])
    assert m.n_points == 1 and m.metadata["time_rows"] == 10
    median = dataclasses.replace(wf, measurements=dataclasses.replace(wf.measurements, time_series="median"))
    with pytest.raises(InputError, match="time_series must be") as err:
        measurements_of(median, ["power"])
    assert err.value.source == "wf.toml" and err.value.field == "measurements.time_series"
    plain = dataclasses.replace(wf, measurements=dataclasses.replace(wf.measurements, time_series=None,
                                                                     average_from=None))
    with pytest.raises(InputError, match=r'\[measurements\] time_series = "mean"'):
        measurements_of(plain, ["power"])
