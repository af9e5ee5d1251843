"""Each filter flags a constructed bad record and not the good ones; every flag is counted."""

from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from calib.errors import InputError
from calib.scada import FilterSettings, apply_filters, frozen_runs, read_scada

RATED = 2000e3
T0 = datetime(2014, 1, 1, tzinfo=timezone.utc)
HEADER = ["Ws_avg", "P_avg", "P_min", "Ba_avg", "Ot_avg", "Rs_avg", "Rs_min"]


def curve_kw(ws):
    return float(np.clip(2.0 * ws ** 3 - 20.0, 0.0, RATED / 1e3))


def campaign(tmp_path, bad: dict):
    """200 good records (distinct wind speeds 4..15 m/s, warm, fine pitch), then the ``bad`` ones
    (name -> cells). Returns the records and the index of each bad one."""
    ws = np.linspace(4.0, 15.0, 200) + 0.001 * np.arange(200) % 0.007
    rows = [[w, curve_kw(w), 0.95 * curve_kw(w), 0.0, 12.0, 14.0, 13.0] for w in ws]
    index = {}
    for name, cells in bad.items():
        index[name] = list(range(len(rows), len(rows) + len(cells)))
        rows += cells
    lines = ["Date_time," + ",".join(HEADER)]
    lines += [(T0 + timedelta(minutes=10 * i)).isoformat() + "," + ",".join(f"{c:.6g}" for c in row)
              for i, row in enumerate(rows)]
    (tmp_path / "f.csv").write_text("\n".join(lines) + "\n")
    return read_scada(tmp_path / "f.csv"), index


BAD = {
    "out_of_range": [[55.0, 100.0, 90.0, 0.0, 12.0, 14.0, 13.0]],
    "frozen": [[7.777, curve_kw(7.777), 0.9 * curve_kw(7.777), 0.0, 12.0, 14.0, 13.0]] * 3,
    "start_stop": [[8.123, 500.0, 0.0, 0.0, 12.0, 14.0, 13.0]],
    "curtailment": [[9.321, 600.0, 550.0, 10.0, 12.0, 14.0, 13.0]],
    "icing": [[9.456, 0.5 * curve_kw(9.456), 0.4 * curve_kw(9.456), 0.0, -2.0, 14.0, 13.0]],
    "good_cold": [[9.654, curve_kw(9.654), 0.9 * curve_kw(9.654), 0.0, -2.0, 14.0, 13.0]],
    "good_pitched_at_rated": [[14.987, RATED / 1e3, 0.98 * RATED / 1e3, 10.0, 12.0, 14.0, 13.0]],
}


@pytest.fixture
def flagged(tmp_path):
    records, index = campaign(tmp_path, BAD)
    return apply_filters(records, FilterSettings(rated_power=RATED, fine_pitch=0.0)), index


@pytest.mark.parametrize("name", ["out_of_range", "frozen", "start_stop", "curtailment", "icing"])
def test_each_filter_flags_its_bad_record_and_nothing_else(flagged, name):
    report, index = flagged
    assert np.flatnonzero(report.flags[name]).tolist() == index[name]
    assert report.counts[name] == len(index[name])


def test_good_records_are_kept_and_everything_is_counted(flagged):
    report, index = flagged
    assert report.kept[:200].all()
    assert report.kept[index["good_cold"]].all() and report.kept[index["good_pitched_at_rated"]].all()
    bad = sum(len(index[n]) for n in ("out_of_range", "frozen", "start_stop", "curtailment", "icing"))
    assert report.counts["removed"] == bad and report.counts["kept"] == 202
    assert "removed (any)" in report.summary()


def test_stop_from_the_rotor_speed_minimum(tmp_path):
    records, index = campaign(tmp_path, {"stop": [[8.2, 500.0, 400.0, 0.0, 12.0, 9.0, 0.0]]})
    report = apply_filters(records, FilterSettings(rated_power=RATED, fine_pitch=0.0))
    assert np.flatnonzero(report.flags["start_stop"]).tolist() == index["stop"]


def test_fine_pitch_estimated_from_partial_load(tmp_path):
    records, _ = campaign(tmp_path, {})
    assert apply_filters(records, FilterSettings(rated_power=RATED)).fine_pitch == 0.0


def test_frozen_runs():
    assert frozen_runs(np.array([1, 2, 2, 2, 3, 3, np.nan, np.nan, np.nan]), 3).tolist() == \
        [False, True, True, True, False, False, False, False, False]


def test_unknown_filter_is_refused():
    with pytest.raises(InputError) as err:
        FilterSettings(rated_power=RATED, enabled=("icing", "stuck"))
    assert err.value.field == "enabled" and "frozen" in str(err.value)


def test_a_filter_without_its_signal_is_reported_not_run(tmp_path):
    path = tmp_path / "short.csv"
    path.write_text("Date_time,Ws_avg,P_avg\n" + "".join(
        f"{(T0 + timedelta(minutes=10 * i)).isoformat()},{5 + 0.01 * i},{100 + i}\n" for i in range(5)))
    report = apply_filters(read_scada(path), FilterSettings(rated_power=RATED))
    assert set(report.not_run) == {"curtailment", "icing"}
    assert "icing            not run: no temperature mean" in report.summary()
