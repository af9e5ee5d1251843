"""read_scada: column map, units, time stamps; bad input is an InputError naming file, line and column,
or a counted flag."""

from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from calib.errors import InputError
from calib.scada import read_scada

T0 = datetime(2014, 1, 1, tzinfo=timezone.utc)


def export(tmp_path, header, rows, name="scada.csv", step=600):
    """A CSV export: ``Date_time`` every ``step`` s, then ``rows`` (lists of cells)."""
    lines = ["Date_time," + ",".join(header)]
    for i, row in enumerate(rows):
        stamp = (T0 + timedelta(seconds=step * i)).isoformat() if not isinstance(row, tuple) else row[0]
        cells = row if not isinstance(row, tuple) else row[1]
        lines.append(stamp + "," + ",".join(str(c) for c in cells))
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


GOOD = [[7.0 + 0.1 * i, 0.3, 900.0 + i, 1.0, 5.0] for i in range(6)]


def test_means_and_std_in_si(tmp_path):
    r = read_scada(export(tmp_path, ["Ws_avg", "Ws_std", "P_avg", "Ba_avg", "Ot_avg"], GOOD))
    assert len(r) == 6
    assert r.get("power")[0] == 900e3                      # kW by default
    assert r.get("temperature")[0] == pytest.approx(278.15)  # °C by default
    assert r.get("wind_speed", "std")[0] == 0.3
    assert not r.flags["missing"].any() and not r.flags["duplicate_stamp"].any()


def test_header_unit_wins_and_std_takes_no_offset(tmp_path):
    rows = [[7.0, 900e3, 280.0, 0.5] for _ in range(3)]
    r = read_scada(export(tmp_path, ["Ws_avg", "P_avg [W]", "Ot_avg [K]", "Ot_std [K]"], rows))
    assert r.get("power")[0] == 900e3 and r.get("temperature")[0] == 280.0
    assert r.get("temperature", "std")[0] == 0.5


def test_missing_required_signal_names_the_header(tmp_path):
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "Ba_avg"], [[7.0, 1.0]]))
    assert err.value.field == "power" and err.value.line == 1 and "scada.csv" in str(err.value)


def test_unknown_column_is_refused_with_a_close_name_and_read_with_a_mapping(tmp_path):
    path = export(tmp_path, ["Ws_avg", "P_avg", "Wss_avg"], [[7.0, 900.0, 7.1]])
    with pytest.raises(InputError) as err:
        read_scada(path)
    assert err.value.field == "Wss_avg" and "did you mean" in str(err.value)
    r = read_scada(path, mapping={"Wss_avg": ("wind_speed", "max", "m/s")})
    assert r.get("wind_speed", "max")[0] == 7.1
    assert len(read_scada(path, ignore=["Wss_avg"])) == 1
    assert "Wss_avg" in " ".join(read_scada(path, unknown="note").notes)


def test_a_bad_mapping_entry_names_its_key(tmp_path):
    path = export(tmp_path, ["Ws_avg", "P_avg"], [[7.0, 900.0]])
    with pytest.raises(InputError) as err:
        read_scada(path, mapping={"X_avg": ("wind_sped", "mean")})
    assert err.value.field == "X_avg"


def test_gaps_are_counted_or_refused(tmp_path):
    rows = [(T0.isoformat(), [7.0, 900.0]), ((T0 + timedelta(minutes=10)).isoformat(), [7.0, 900.0]),
            ((T0 + timedelta(minutes=40)).isoformat(), [7.1, 910.0])]
    path = export(tmp_path, ["Ws_avg", "P_avg"], rows)
    assert read_scada(path).gaps == {"": 2}
    with pytest.raises(InputError) as err:
        read_scada(path, gaps="error")
    assert err.value.line == 4 and err.value.field == "Date_time"


def test_duplicate_stamps_are_flagged_or_refused(tmp_path):
    rows = [(T0.isoformat(), [7.0, 900.0]), (T0.isoformat(), [7.2, 950.0]),
            ((T0 + timedelta(minutes=10)).isoformat(), [7.1, 910.0])]
    path = export(tmp_path, ["Ws_avg", "P_avg"], rows)
    r = read_scada(path)
    assert r.flags["duplicate_stamp"].tolist() == [False, True, False]
    assert r.get("power")[0] == 900e3                      # the first record of the stamp is the one kept
    with pytest.raises(InputError) as err:
        read_scada(path, duplicates="error")
    assert err.value.line == 3


def test_temperature_in_kelvin_read_as_celsius_is_refused(tmp_path):
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg", "Ot_avg"], [[7.0, 900.0, 281.0]] * 3))
    assert err.value.field == "Ot_avg" and "look like K" in str(err.value)


def test_density_in_the_wrong_unit_is_refused(tmp_path):
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg", "Air_density_avg"], [[7.0, 900.0, 1225.0]] * 3))
    assert err.value.field == "Air_density_avg"
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg", "Air_density_avg [g/m^3]"], [[7.0, 900.0, 1225.0]]))
    assert err.value.field == "Air_density_avg [g/m^3]" and "kg/m^3" in str(err.value)


def test_pressure_in_pa_read_as_hpa_is_refused(tmp_path):
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg", "Pr_avg"], [[7.0, 900.0, 101325.0]] * 3))
    assert err.value.field == "Pr_avg" and "Pa" in str(err.value)


def test_negative_sigma_names_line_and_column(tmp_path):
    rows = [[7.0, 0.3, 900.0], [7.1, -0.2, 910.0]]
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "Ws_std", "P_avg"], rows))
    assert (err.value.line, err.value.field) == (3, "Ws_std")


def test_a_missing_value_is_a_flag_and_text_an_error(tmp_path):
    r = read_scada(export(tmp_path, ["Ws_avg", "P_avg"], [[7.0, 900.0], ["", 900.0], [7.0, "NaN"]]))
    assert r.flags["missing"].tolist() == [False, True, True]
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg"], [[7.0, 900.0], ["seven", 900.0]]))
    assert (err.value.line, err.value.field) == (3, "Ws_avg")


def test_turbines_sorted_and_selected(tmp_path):
    path = tmp_path / "farm.csv"
    path.write_text("Wind_turbine_name;Date_time;Ws_avg;P_avg\n"
                    "B;2014-01-01T01:00:00+01:00;7;900\nA;2014-01-01T01:00:00+01:00;8;1000\n"
                    "B;2014-01-01T01:10:00+01:00;7.5;950\n")
    r = read_scada(path)
    assert r.turbine.tolist() == ["A", "B", "B"] and r.gaps == {"A": 0, "B": 0}
    assert r.time[0] == T0.timestamp()
    assert np.all(read_scada(path, turbine="B").turbine == "B")


def test_a_unit_the_signal_does_not_take_is_refused(tmp_path):
    with pytest.raises(InputError) as err:
        read_scada(export(tmp_path, ["Ws_avg", "P_avg [kWh]"], [[7.0, 900.0]]))
    assert err.value.field == "P_avg [kWh]" and "kW" in str(err.value)
