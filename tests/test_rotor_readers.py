"""AeroDyn 15 and windIO readers on every shipped file, and every bad-input path."""

import re
from pathlib import Path

import numpy as np
import pytest

from calib.errors import InputError
from calib.rotor.aerodyn import read_aerodyn_blade, read_aerodyn_polar, rotor_from_aerodyn
from calib.rotor.aerodyn_main import read_aerodyn_afnames
from calib.rotor.library import DATA_DIR
from calib.rotor.windio import nearest_airfoil_labels, read_windio

NREL_BLADE = DATA_DIR / "nrel5mw" / "NRELOffshrBsline5MW_AeroDyn_blade.dat"
NREL_POLAR = DATA_DIR / "nrel5mw" / "Airfoils" / "DU25_A17.dat"
IEA34_YAML = DATA_DIR / "iea3p4" / "IEA-3.4-130-RWT_windIO.yaml"
TWO_TABLES_FILE = Path(__file__).parent / "data" / "bad_inputs" / "two_tables_AD15.dat"
IEA15_YAML = DATA_DIR / "iea15" / "IEA-15-240-RWT_windIO.yaml"


# ---------------------------------------------------------------- shipped files
@pytest.mark.parametrize("folder, blade, n_nodes, last_span, first_chord", [
    ("nrel5mw", "NRELOffshrBsline5MW_AeroDyn_blade.dat", 19, 61.4999, 3.542),
    ("iea3p4", "IEA-3.4-130-RWT_AeroDyn15_blade.dat", 30, 62.90852112228899, 2.6),
    ("iea15", "IEA-15-240-RWT_AeroDyn15_blade.dat", 50, 116.9999315223028, 5.2),
])
def test_blade_files(folder, blade, n_nodes, last_span, first_chord):
    b = read_aerodyn_blade(DATA_DIR / folder / blade)
    for key in ("span", "curve_ac", "sweep_ac", "curve_angle", "twist", "chord", "af_id", "line"):
        assert b[key].shape == (n_nodes,)
    assert b["span"][0] == 0.0 and b["span"][-1] == pytest.approx(last_span)
    assert b["chord"][0] == pytest.approx(first_chord)
    assert b["af_id"].min() == 1


def test_nrel5mw_blade_follows_numblnds_not_the_extra_row():
    b = read_aerodyn_blade(NREL_BLADE)
    assert b["span"].size == 19
    assert b["span"][-1] == pytest.approx(61.4999)  # the 20th row (61.5) after the comment is ignored
    assert b["twist"][0] == pytest.approx(13.308)
    np.testing.assert_array_equal(b["af_id"], [1, 1, 1, 2, 3, 4, 4, 5, 6, 6, 7, 7, 8, 8, 8, 8, 8, 8, 8])
    assert b["line"][0] == 7 and b["line"][-1] == 25


@pytest.mark.parametrize("folder, main, n_files", [
    ("nrel5mw", "NREL5MW_AD15_main_input.dat", 8),
    ("iea3p4", "IEA-3.4-130-RWT_AeroDyn15.dat", 30),
    ("iea15", "IEA-15-240-RWT-Monopile_AeroDyn15_main_input.dat", 50),
])
def test_afnames_and_every_shipped_polar(folder, main, n_files):
    names = read_aerodyn_afnames(DATA_DIR / folder / main)
    assert len(names) == n_files
    for name in names:
        af = read_aerodyn_polar(DATA_DIR / folder / "Airfoils" / name.replace("\\", "/").split("/")[-1])
        assert len(af.tables) == 1
        table = af.tables[0]
        assert table.covers_full_circle
        assert table.reynolds > 1e5  # millions converted to absolute
        assert np.all(table.cd > 0)


def test_nrel5mw_afnames_order_and_du25_values():
    names = read_aerodyn_afnames(DATA_DIR / "nrel5mw" / "NREL5MW_AD15_main_input.dat")
    assert names[0] == "../5MW_Baseline/Airfoils/Cylinder1.dat"
    assert names[-1].endswith("NACA64_A17.dat")
    af = read_aerodyn_polar(NREL_POLAR)
    t = af.tables[0]
    assert t.reynolds == pytest.approx(0.75e6)
    assert t.alpha_deg.size == 140
    assert (t.alpha_deg[1], t.cl[1], t.cd[1], t.cm[1]) == pytest.approx((-175.0, 0.368, 0.0324, 0.1845))
    cyl = read_aerodyn_polar(DATA_DIR / "nrel5mw" / "Airfoils" / "Cylinder1.dat").tables[0]
    assert np.all(cyl.cd == 0.5) and np.all(cyl.cl == 0.0)


def test_rotor_from_aerodyn_nrel5mw():
    folder = DATA_DIR / "nrel5mw"
    names = read_aerodyn_afnames(folder / "NREL5MW_AD15_main_input.dat")
    rotor = rotor_from_aerodyn(NREL_BLADE, [folder / "Airfoils" / n.split("/")[-1] for n in names],
                               hub_radius=1.5, n_blades=3, precone_deg=2.5, tilt_deg=5.0, hub_height=90.0,
                               name="t")
    assert rotor.tip_radius == pytest.approx(63.0, abs=2e-4)
    assert rotor.r[0] == pytest.approx(1.5)
    assert rotor.airfoil_id[0] == 0 and rotor.airfoil_id[-1] == 7
    assert rotor.airfoils[rotor.airfoil_id[-1]].name == "NACA64_A17"
    assert rotor.precurve[5] == pytest.approx(1.1573354e-01)   # -BlCrvAC (CCBlade sign)
    assert rotor.presweep_tip == pytest.approx(-1.7737470e-01)


# ---------------------------------------------------------------- windIO
def test_windio_iea34_against_its_aerodyn_blade():
    """Same turbine, two files: windIO on 30 equally spaced stations vs AeroDyn's 30 nodes."""
    rotor = read_windio(IEA34_YAML)
    blade = read_aerodyn_blade(DATA_DIR / "iea3p4" / "IEA-3.4-130-RWT_AeroDyn15_blade.dat")
    assert rotor.n_stations == 30 and rotor.n_blades == 3
    assert rotor.hub_radius == pytest.approx(2.0)
    assert rotor.tip_radius == pytest.approx(65.0)  # rotor diameter 130 m
    assert rotor.precone_deg == pytest.approx(3.0, abs=1e-3)
    assert rotor.tilt_deg == pytest.approx(5.0, abs=1e-3)
    assert rotor.hub_height == pytest.approx(110.0)
    np.testing.assert_allclose(rotor.chord, blade["chord"], rtol=0.01)
    np.testing.assert_allclose(rotor.twist_deg, blade["twist"], atol=0.1)
    # precurve sign: windIO x and AeroDyn BlCrvAC agree (negative = upwind prebend); the Rotor
    # stores the CCBlade sign (positive away from the tower)
    assert -rotor.precurve_tip == pytest.approx(blade["curve_ac"][-1]) == pytest.approx(-2.5)
    np.testing.assert_allclose(-rotor.precurve, blade["curve_ac"], atol=0.1)
    # nearest airfoil: root cylinder, tip DU08-W-210
    assert rotor.airfoils[rotor.airfoil_id[0]].name == "cylinder"
    assert rotor.airfoils[rotor.airfoil_id[-1]].name == "DU08-W-210"
    assert rotor.airfoils[rotor.airfoil_id[-1]].relative_thickness == pytest.approx(0.21)
    assert all(a.tables[0].covers_full_circle for a in rotor.airfoils)
    assert rotor.schedule.min_rotor_speed == pytest.approx(6.9, abs=1e-3)
    assert rotor.schedule.design_tsr == pytest.approx(8.01754386)


def test_windio_iea15_against_its_aerodyn_blade():
    rotor = read_windio(IEA15_YAML, n_stations=50)
    blade = read_aerodyn_blade(DATA_DIR / "iea15" / "IEA-15-240-RWT_AeroDyn15_blade.dat")
    assert rotor.tip_radius == pytest.approx(241.94 / 2, abs=1e-3)
    np.testing.assert_allclose(rotor.r - rotor.hub_radius, blade["span"], atol=1e-3)
    np.testing.assert_allclose(rotor.chord, blade["chord"], rtol=0.01)
    np.testing.assert_allclose(rotor.twist_deg, blade["twist"], atol=0.1)
    np.testing.assert_allclose(-rotor.precurve, blade["curve_ac"], atol=0.1)
    assert rotor.precone_deg == pytest.approx(4.0) and rotor.tilt_deg == pytest.approx(6.0)
    assert rotor.airfoils[rotor.airfoil_id[-1]].name == "FFA-W3-211"


def test_nearest_airfoil_rule():
    labels = nearest_airfoil_labels([0.0, 0.5, 1.0], ["a", "b", "c"], [0.0, 0.2, 0.25, 0.3, 0.8, 1.0])
    assert labels == ["a", "a", "a", "b", "c", "c"]  # 0.25 is a tie: inboard wins


def test_windio_missing_key_names_the_field(tmp_path):
    text = IEA34_YAML.read_text().replace("cone_angle:", "cone_angle_typo:")
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(InputError) as err:
        read_windio(path)
    assert err.value.field == "components.hub.cone_angle" and "broken.yaml" in str(err.value)


# ---------------------------------------------------------------- bad inputs
def _edit(tmp_path, source, name, old, new, count=1):
    text = source.read_text()
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new, count))
    return path


def _assert_where(err, path, line, field):
    msg = str(err.value)
    assert err.value.source == str(path) and str(path) in msg
    assert err.value.line == line and f"line {line}" in msg
    assert err.value.field == field and f"'{field}'" in msg


def test_blade_numblnds_larger_than_rows(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "         19   NumBlNds", "         22   NumBlNds")
    with pytest.raises(InputError, match="only 20 data rows") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 4, "NumBlNds")


def test_blade_missing_numblnds(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "         19   NumBlNds", "         19   NumNodes")
    with pytest.raises(InputError) as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 5, "NumBlNds")  # reported at the column header it should precede


def test_blade_non_numeric_field(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "4.1670000E+00", "4.1x70000E+00")
    with pytest.raises(InputError, match="expected a number") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 10, "BlChord")


def test_blade_short_row(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", " 1.3308000E+01  3.8540000E+00        1", "")
    with pytest.raises(InputError, match="expected 7 columns") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 9, "BlTwist")


def test_blade_negative_chord(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "4.6520000E+00", "-4.6520000E+00")
    with pytest.raises(InputError, match="chord must be > 0") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 12, "BlChord")


def test_blade_span_not_increasing(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "1.8450000E+01", "1.2450000E+01")
    with pytest.raises(InputError, match="strictly increasing") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 13, "BlSpn")


def test_station_outside_hub_tip(tmp_path):
    path = _edit(tmp_path, NREL_BLADE, "b.dat", "0.0000000E+00  0.0000000E+00  0.0000000E+00 0.0000000E+00",
                 "-0.500000E+00  0.0000000E+00  0.0000000E+00 0.0000000E+00")
    with pytest.raises(InputError, match="BlSpn") as err:
        read_aerodyn_blade(path)
    _assert_where(err, path, 7, "BlSpn")
    polars = sorted((DATA_DIR / "nrel5mw" / "Airfoils").glob("*.dat"))
    with pytest.raises(InputError, match="outside") as err:  # beyond a given tip radius
        rotor_from_aerodyn(NREL_BLADE, polars, 1.5, 3, 2.5, 5.0, 90.0, "t", tip_radius=60.0)
    _assert_where(err, NREL_BLADE, 24, "BlSpn")  # r = 61.63 m


def test_blade_airfoil_id_beyond_files(tmp_path):
    polars = sorted((DATA_DIR / "nrel5mw" / "Airfoils").glob("*.dat"))[:7]
    with pytest.raises(InputError, match="BlAFID = 8") as err:
        rotor_from_aerodyn(NREL_BLADE, polars, 1.5, 3, 2.5, 5.0, 90.0, "t")
    _assert_where(err, NREL_BLADE, 19, "BlAFID")


def test_polar_numalf_larger_than_rows(tmp_path):
    path = _edit(tmp_path, NREL_POLAR, "p.dat", "140   NumAlf", "150   NumAlf")
    with pytest.raises(InputError, match="NumAlf = 150 but only 140") as err:
        read_aerodyn_polar(path)
    line = 1 + NREL_POLAR.read_text().splitlines().index(
        next(ln for ln in NREL_POLAR.read_text().splitlines() if "NumAlf" in ln))
    _assert_where(err, path, line, "NumAlf")


def test_polar_numalf_smaller_than_rows(tmp_path):
    path = _edit(tmp_path, NREL_POLAR, "p.dat", "140   NumAlf", "139   NumAlf")
    with pytest.raises(InputError, match="another data row") as err:
        read_aerodyn_polar(path)
    assert err.value.field == "NumAlf" and err.value.line == 52


def test_polar_short_table_before_next_table(tmp_path):
    text = _edit(tmp_path, TWO_TABLES_FILE, "two.dat", "          5   NumAlf", "          6   NumAlf")
    with pytest.raises(InputError, match="NumAlf = 6 but only 5") as err:
        read_aerodyn_polar(text)
    _assert_where(err, text, 11, "NumAlf")


def test_polar_missing_numalf_and_wrong_numtabs(tmp_path):
    path = _edit(tmp_path, TWO_TABLES_FILE, "two.dat", "          2   NumTabs", "          3   NumTabs")
    with pytest.raises(InputError, match="NumTabs = 3 but the file has 2") as err:
        read_aerodyn_polar(path)
    _assert_where(err, path, 6, "NumTabs")
    path = _edit(tmp_path, TWO_TABLES_FILE, "two.dat", "          4   NumAlf", "          4   NumRows")
    with pytest.raises(InputError) as err:
        read_aerodyn_polar(path)
    assert err.value.field == "NumTabs"  # one NumAlf line for two tables


def test_polar_non_numeric_field(tmp_path):
    path = _edit(tmp_path, NREL_POLAR, "p.dat", "   -175.00    0.368   0.0324", "   -175.00    0.368   abc")
    with pytest.raises(InputError, match="expected a number") as err:
        read_aerodyn_polar(path)
    _assert_where(err, path, 56, "Cd")


def test_polar_non_numeric_count(tmp_path):
    path = _edit(tmp_path, NREL_POLAR, "p.dat", "140   NumAlf", "1x0   NumAlf")
    with pytest.raises(InputError, match="integer") as err:
        read_aerodyn_polar(path)
    _assert_where(err, path, 52, "NumAlf")


def test_polar_non_monotone_alpha(tmp_path):
    path = _edit(tmp_path, NREL_POLAR, "p.dat", "   -170.00    0.735", "   -176.00    0.735")
    with pytest.raises(InputError, match="strictly increasing") as err:
        read_aerodyn_polar(path)
    _assert_where(err, path, 57, "Alpha")


def test_afnames_too_few(tmp_path):
    main = DATA_DIR / "nrel5mw" / "NREL5MW_AD15_main_input.dat"
    path = _edit(tmp_path, main, "m.dat", "          8   NumAFfiles", "          9   NumAFfiles")
    with pytest.raises(InputError, match="only 8") as err:
        read_aerodyn_afnames(path)
    line = 1 + next(i for i, ln in enumerate(main.read_text().splitlines()) if "NumAFfiles" in ln)
    _assert_where(err, path, line, "NumAFfiles")


def test_missing_file_is_named():
    with pytest.raises(InputError, match=re.escape("no_such_file.dat")):
        read_aerodyn_polar("no_such_file.dat")
