"""IEC 61400-12-1 measurement categories A and B in the AEP uncertainty (issue 41 item 3), against a hand
computation, and the measured wind-speed histogram input (item 4)."""

import numpy as np
import pytest

from calib.errors import InputError
from calib.powercurve.measurement import MeasurementItem, aep_uncertainty, parse_measurement


def test_categories_combine_as_the_standard_does_against_a_hand_computation():
    # a linear power curve, 100 W per m/s: np.gradient's slope is exact at every bin, the ends included
    v = np.array([4.0, 5.0, 6.0, 7.0])
    P = np.array([100.0, 200.0, 300.0, 400.0])
    c = np.array([1.0, 2.0, 3.0, 4.0])
    items = [MeasurementItem("transducer", "power", 0.01, "B"),      # u = 1, 2, 3, 4 W
             MeasurementItem("scatter", "power", 0.02, "A"),         # u = 2, 4, 6, 8 W
             MeasurementItem("anemometer", "wind", 0.02, "B"),       # u_V = 0.02 V: u = 8, 10, 12, 14 W
             MeasurementItem("density", "density", 0.03, "B")]       # u_V = 0.01 V: u = 4, 5, 6, 7 W
    out = aep_uncertainty(items, v, P, c)
    # by hand: B linear over the bins, Σ c_i u_i; A in quadrature, (Σ c_i² u_i²)^½
    hand = {"transducer": 1 + 4 + 9 + 16, "scatter": np.sqrt(2 ** 2 + 8 ** 2 + 18 ** 2 + 32 ** 2),
            "anemometer": 8 + 20 + 36 + 56, "density": 4 + 10 + 18 + 28}
    for k, x in hand.items():
        assert out["items"][k] == pytest.approx(x, rel=1e-12), k
    assert out["A"] == pytest.approx(np.sqrt(1416.0), rel=1e-12)
    assert out["B"] == pytest.approx(np.sqrt(30.0 ** 2 + 120.0 ** 2 + 60.0 ** 2), rel=1e-12)
    assert out["total"] == pytest.approx(np.sqrt(1416.0 + 30.0 ** 2 + 120.0 ** 2 + 60.0 ** 2), rel=1e-12)
    # the same item as category A is smaller than as B (positive weights): independence averages out
    a = aep_uncertainty([MeasurementItem("t", "power", 0.01, "A")], v, P, c)["total"]
    assert a == pytest.approx(np.sqrt(1 + 16 + 81 + 256)) and a < 30


def test_the_category_is_parsed_and_a_bad_one_named():
    assert parse_measurement("scatter=power:1:A") == MeasurementItem("scatter", "power", 0.01, "A")
    assert parse_measurement("anemometer=wind:2%").category == "B"
    assert parse_measurement("cup = wind : 2 % : b").category == "B"
    with pytest.raises(InputError, match=r"unknown category 'C'.*A \(uncorrelated across bins\)"):
        parse_measurement("x=wind:2:C")


def _write(tmp_path, text, name="h.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_histogram_in_hours_becomes_frequencies_and_a_piecewise_linear_cdf(tmp_path):
    from calib.powercurve.histogram import read_wind_histogram
    h = read_wind_histogram(_write(tmp_path, "# site A\nwind_speed [m/s],hours [h]\n4,1000\n6,3000\n"))
    np.testing.assert_allclose(h.frequency, [0.25, 0.75])
    assert h.hours == 4000
    np.testing.assert_allclose(h.edges, [3.0, 5.0, 7.0])
    # uniform within a bin: F(4) = half the first bin, F(6) = first + half the second
    np.testing.assert_allclose(h.cdf([2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 9.0]), [0, 0, 0.125, 0.25, 0.625, 1, 1])
    assert h.mean == pytest.approx(5.5)
    f = read_wind_histogram(_write(tmp_path, "frequency,wind_speed\n0.5,3\n0.5,4\n", "f.csv"))
    assert f.hours is None and f.mean == pytest.approx(3.5)


@pytest.mark.parametrize("text, where", [
    ("speed,hours\n4,1\n5,2\n", r"line 1.*wind_speed \[m/s\] and one of hours"),
    ("wind_speed,hours,frequency\n4,1,0.5\n5,2,0.5\n", r"line 1.*one of hours"),
    ("wind_speed,hours\n4,1\n5,abc\n", r"line 3, field 'hours'.*column 2 \(hours\): 'abc' is not a finite number"),
    ("wind_speed,hours\n4,1\n5,-2\n", r"line 3, field 'hours'.*column 2"),
    ("# c\nwind_speed,hours\n4,1\n\n6,2\n5,1\n", r"line 6, field 'wind_speed'.*must increase \(5 after 6\)"),
    ("wind_speed,hours\n4,1\n5\n", r"line 3.*1 cells where the header has 2"),
    ("wind_speed,hours\n4,1\n", r"at least two bins"),
    ("wind_speed,frequency\n4,0\n5,0\n", r"every bin is zero"),
    ("# only a comment\n", r"empty"),
])
def test_a_bad_histogram_names_its_file_line_and_column(tmp_path, text, where):
    from calib.powercurve.histogram import read_wind_histogram
    p = _write(tmp_path, text)
    with pytest.raises(InputError, match=where) as info:
        read_wind_histogram(p)
    assert str(p) in str(info.value)
