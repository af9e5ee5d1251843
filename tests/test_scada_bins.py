"""The method of bins against a hand computation, and bins and records as calib measurement tables."""

import numpy as np
import pytest

from calib.errors import InputError
from calib.measurements import read_measurements
from calib.scada import bin_index, method_of_bins, write_bins_table, write_records_table


def test_bins_by_hand():
    # bin centred on 1.0 m/s ([0.75, 1.25)): 1.0, 1.1, 1.2 -> P 10, 20, 30: N 3, mean 20, σ 10, σ/√3 = 5.7735
    # 1.25 falls in the bin centred on 1.5; 3.0 alone in its bin
    b = method_of_bins([1.0, 1.1, 1.2, 1.25, 3.0], [10.0, 20.0, 30.0, 50.0, 40.0],
                       conditions={"pitch": [0.0, 1.0, 2.0, 5.0, 3.0]})
    assert b.centre.tolist() == [1.0, 1.5, 3.0]
    assert b.n.tolist() == [3, 1, 1]
    assert b.wind_speed[0] == pytest.approx(1.1)
    assert b.power[0] == pytest.approx(20.0)
    assert b.power_std[0] == pytest.approx(10.0)
    assert b.power_sigma[0] == pytest.approx(10.0 / np.sqrt(3))
    assert b.conditions["pitch"]["std"][0] == pytest.approx(1.0)
    assert np.isnan(b.power_sigma[1])


def test_left_aligned_bins_as_openoa():
    b = method_of_bins([1.0, 1.1, 1.49, 1.5], [1.0, 2.0, 3.0, 4.0], align="left")
    assert b.lower.tolist() == [1.0, 1.5]
    assert b.n.tolist() == [3, 1]
    assert bin_index([1.2, 1.7, 9.0, np.nan], b).tolist() == [0, 1, -1, -1]


def test_non_finite_records_are_in_no_bin():
    b = method_of_bins([1.0, np.nan, 1.1], [1.0, 2.0, np.nan])
    assert b.n.tolist() == [1]


def _bins():
    rng = np.random.default_rng(1)
    ws = rng.uniform(4.0, 8.0, 200)
    return method_of_bins(ws, 1e4 * ws ** 3 + rng.normal(0, 1e3, 200),
                          conditions={"pitch": rng.normal(0.0, 0.2, 200), "rotor_speed": 10 + ws}), ws


def test_bins_table_reads_as_calib_measurements(tmp_path):
    bins, _ = _bins()
    path = write_bins_table(bins, tmp_path / "bins.csv", comments=["test"])
    m = read_measurements(path)
    sel = bins.n >= 3
    assert m.channels == ("power",)
    assert np.allclose(m.values[:, 0], bins.power[sel])
    assert np.allclose(m.sigma[:, 0], bins.power_sigma[sel])
    assert np.allclose(m.conditions.wind_speed, bins.wind_speed[sel])
    assert "wind_speed_sigma" in path.read_text().splitlines()[2]


def test_records_table_with_the_bin_scatter_as_sigma(tmp_path):
    bins, ws = _bins()
    path = write_records_table({"wind_speed": ws, "pitch": np.zeros_like(ws), "rotor_speed": 10 + ws},
                               1e4 * ws ** 3, bins, tmp_path / "records.csv")
    m = read_measurements(path)
    assert len(m.values) == ws.size
    k = bin_index(ws, bins)
    assert np.allclose(m.sigma[:, 0], bins.power_std[k])


def test_a_table_without_rotor_speed_is_refused_unless_filled(tmp_path):
    b = method_of_bins([5.0, 5.1, 5.2], [1.0, 2.0, 3.0], conditions={"pitch": [0.0, 0.0, 0.0]})
    with pytest.raises(InputError) as err:
        write_bins_table(b, tmp_path / "b.csv")
    assert err.value.field == "rotor_speed"
    path = write_bins_table(b, tmp_path / "b.csv", fill={"rotor_speed": 17.0})
    assert read_measurements(path).conditions.rotor_speed.tolist() == [17.0]
