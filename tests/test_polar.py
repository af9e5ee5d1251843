"""Polars: Viterna extrapolation, full-circle padding, multi-table files, Re interpolation."""

from pathlib import Path

import numpy as np
import pytest

from calib.errors import InputError
from calib.rotor.aerodyn import read_aerodyn_polar
from calib.rotor.library import reference_path
from calib.rotor.polar import PolarTable
from calib.rotor.viterna import cd_max_from_aspect_ratio, densify_full_circle, extrapolate_viterna


def _s809_certtest():
    return read_aerodyn_polar(reference_path("S809_AD15.dat")).tables[0]


def _limited(alpha_lo=-20.1, alpha_hi=39.9):
    t = _s809_certtest()
    m = (t.alpha_deg >= alpha_lo) & (t.alpha_deg <= alpha_hi)
    return t, m, PolarTable(t.alpha_deg[m], t.cl[m], t.cd[m], t.cm[m], t.reynolds, source="cropped")


def test_viterna_reproduces_airfoilprep_extension_of_certtest_polar():
    """S809_AD15.dat was extended by AirfoilPrep from 39.9 deg with C_D,max = 1.29: crop it
    back to the measured range, extend again, compare with the file (independent output)."""
    full, measured, cropped = _limited()
    ext = extrapolate_viterna(cropped, cd_max=1.29, n_alpha=400)
    far = np.abs(full.alpha_deg) >= 40.0
    a = full.alpha_deg[far]
    np.testing.assert_allclose(np.interp(a, ext.alpha_deg, ext.cl), full.cl[far], atol=2e-3)
    np.testing.assert_allclose(np.interp(a, ext.alpha_deg, ext.cd), full.cd[far], atol=2e-3)
    pos = a > 0
    np.testing.assert_allclose(np.interp(a[pos], ext.alpha_deg, ext.cm), full.cm[far][pos], atol=2e-3)


def test_viterna_covers_full_circle_and_keeps_table_rows():
    _, _, cropped = _limited(alpha_hi=26.1)
    ext = extrapolate_viterna(cropped, aspect_ratio=11)
    assert ext.covers_full_circle
    assert ext.alpha_deg[0] == -180.0 and ext.alpha_deg[-1] == 180.0
    inside = np.isin(ext.alpha_deg, cropped.alpha_deg)
    assert inside.sum() == cropped.alpha_deg.size
    np.testing.assert_array_equal(ext.cl[inside], cropped.cl)
    np.testing.assert_array_equal(ext.cd[inside], cropped.cd)


def test_viterna_is_continuous_and_zero_lift_at_90_and_180():
    _, _, cropped = _limited(alpha_hi=26.1)
    ext = extrapolate_viterna(cropped, aspect_ratio=11, n_alpha=2000)
    outside = (ext.alpha_deg > 26.1) | (ext.alpha_deg < -20.1)
    seg = outside[1:] & outside[:-1]
    # on a fine grid a continuous curve has small steps; a junction mismatch would not shrink
    assert np.max(np.abs(np.diff(ext.cl))[seg]) < 0.01
    assert np.max(np.abs(np.diff(ext.cd))[seg]) < 0.01
    for a in (-180.0, 180.0, -90.0, 90.0):
        assert abs(np.interp(a, ext.alpha_deg, ext.cl)) < 1e-3
    assert np.interp(90.0, ext.alpha_deg, ext.cd) == pytest.approx(cd_max_from_aspect_ratio(11), abs=1e-3)
    # continuity at the matching point from both sides
    i = int(np.flatnonzero(ext.alpha_deg == 26.1)[0])
    assert abs(ext.cl[i + 1] - ext.cl[i]) < 0.01 and abs(ext.cd[i + 1] - ext.cd[i]) < 0.01


def test_cd_max_rules():
    assert cd_max_from_aspect_ratio(10) == pytest.approx(1.29)
    assert cd_max_from_aspect_ratio(500) == pytest.approx(1.11 + 0.018 * 50)
    _, _, cropped = _limited(alpha_hi=26.1)
    flat = extrapolate_viterna(cropped)  # neither given: flat plate 2.0
    assert np.interp(90.0, flat.alpha_deg, flat.cd) == pytest.approx(2.0, abs=1e-3)
    small = extrapolate_viterna(cropped, cd_max=0.1)  # raised to the table's largest C_D
    assert np.interp(90.0, small.alpha_deg, small.cd) == pytest.approx(cropped.cd.max(), abs=1e-3)
    with pytest.raises(InputError):
        cd_max_from_aspect_ratio(-1)


def test_viterna_leaves_full_circle_tables_alone_and_rejects_bad_range():
    full = _s809_certtest()
    assert extrapolate_viterna(full) is full
    bad = PolarTable([-10.0, 0.0, 95.0, 100.0], [0, 0, 0, 0], [0.01] * 4)
    with pytest.raises(InputError, match="last angle"):
        extrapolate_viterna(bad)


def test_densify_full_circle_keeps_linear_polar():
    a, cl, cd, cm = densify_full_circle([-180.0, 180.0], [0.0, 0.0], [0.5, 0.7], None, min_points=4)
    assert a.size >= 4 and cm is None
    np.testing.assert_allclose(cd, np.interp(a, [-180, 180], [0.5, 0.7]))
    a2, *_ = densify_full_circle([-10.0, 10.0], [0, 1], [0, 0], min_points=4)
    assert a2.size == 2  # not full circle: untouched


TWO_TABLES_FILE = Path(__file__).parent / "data" / "bad_inputs" / "two_tables_AD15.dat"  # 2 tables, Re 0.5e6 and 1.5e6


def test_multi_table_file_and_reynolds_interpolation():
    af = read_aerodyn_polar(TWO_TABLES_FILE)
    assert af.name == "two_tables_AD15"
    np.testing.assert_allclose(af.reynolds_numbers, [0.5e6, 1.5e6])
    assert [t.alpha_deg.size for t in af.tables] == [5, 4]
    assert af.tables[1].first_line == 26  # line of "-180.0 0.0 0.40 0.0"
    mid = af.at_reynolds(1.0e6)
    assert np.interp(0.0, mid.alpha_deg, mid.cl) == pytest.approx(0.3)
    assert np.interp(10.0, mid.alpha_deg, mid.cd) == pytest.approx(0.04)
    assert np.interp(0.0, af.at_reynolds(5e6).alpha_deg, af.at_reynolds(5e6).cl) == pytest.approx(0.4)
