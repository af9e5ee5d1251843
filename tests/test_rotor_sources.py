"""Rotors from OpenFAST decks and the [rotor] table: calib.rotor.openfast and calib.rotor.sources.

Reference for the r-test deck: the embedded ``nrel5mw`` rotor, built from another copy of the
NREL 5-MW files (welib, calib/data/nrel5mw) with hub radius, precone, tilt and hub height typed
from the NREL report (TP-500-38060), so a wrong sign or formula in the deck reader shows.
"""

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from calib.bem.solver import BemSettings
from calib.errors import InputError
from calib.models.bem_model import BemModel
from calib.rotor.aerodyn_main import read_aerodyn_main
from calib.rotor.library import DATA_DIR, load_rotor
from calib.rotor.openfast import read_elastodyn
from calib.rotor.sources import RotorSource, rotor_from_table
from calib.types import OperatingConditions, Status

DATA = Path(__file__).parent / "data"
DECK = DATA / "openfast" / "5MW_Land_DLL_WTurb"
FST = DECK / "5MW_Land_DLL_WTurb.fst"
ED = DECK / "NRELOffshrBsline5MW_Onshore_ElastoDyn.dat"
AD_GEN1 = DECK / "NRELOffshrBsline5MW_Onshore_AeroDyn15.dat"   # WakeMod / AFAeroMod
AD_GEN2 = DECK / "NRELOffshrBsline5MW_Onshore_AeroDyn.dat"     # Wake_Mod / UA_Mod (OpenFAST 4)
BASELINE = DATA / "openfast" / "5MW_Baseline"
WORKFLOW = "workflow.toml"
NREL_SETUP = {"hub_radius": 1.5, "precone": 2.5, "tilt": 5.0, "hub_height": 90.0, "n_blades": 3}


# ---------------------------------------------------------------- helpers
@pytest.fixture
def deck(tmp_path):
    """A writable copy of the r-test files (relative layout kept); returns the .fst path."""
    shutil.copytree(DATA / "openfast", tmp_path / "openfast")
    return tmp_path / "openfast" / "5MW_Land_DLL_WTurb" / FST.name


def line_of(path, keyword) -> int:
    """1-based line whose second token is ``keyword`` (found independently of the reader)."""
    for i, line in enumerate(Path(path).read_text().splitlines(), start=1):
        tokens = line.split()
        if len(tokens) >= 2 and tokens[1] == keyword:
            return i
    raise AssertionError(f"{keyword} not in {path}")


def set_value(path, keyword, value):
    """Replace the value on the ``keyword`` line of an OpenFAST input file."""
    lines = Path(path).read_text().splitlines(keepends=True)
    i = line_of(path, keyword) - 1
    lines[i] = f"{value:>11}   {keyword}{lines[i].split(keyword, 1)[1]}"
    Path(path).write_text("".join(lines))


def delete_lines(path, keywords):
    lines = Path(path).read_text().splitlines(keepends=True)
    drop = {line_of(path, k) - 1 for k in keywords}
    Path(path).write_text("".join(ln for i, ln in enumerate(lines) if i not in drop))


def from_openfast(fst) -> RotorSource:
    return rotor_from_table({"openfast": str(fst)}, WORKFLOW, ".")


# ---------------------------------------------------------------- geometry vs the embedded rotor
def test_rtest_deck_gives_the_embedded_nrel5mw_geometry():
    rotor = from_openfast(FST).rotor
    ref = load_rotor("nrel5mw")
    for name in ("r", "chord", "twist_deg", "airfoil_id", "precurve", "presweep"):
        np.testing.assert_array_equal(getattr(rotor, name), getattr(ref, name), err_msg=name)
    assert [a.name for a in rotor.airfoils] == [a.name for a in ref.airfoils]
    for mine, theirs in zip(rotor.airfoils, ref.airfoils):   # same tables, other file headers
        for t1, t2 in zip(mine.tables, theirs.tables, strict=True):
            for field in ("alpha_deg", "cl", "cd", "cm"):
                np.testing.assert_array_equal(getattr(t1, field), getattr(t2, field))
    assert (rotor.n_blades, rotor.hub_radius, rotor.tip_radius) == (ref.n_blades, ref.hub_radius, ref.tip_radius)
    assert rotor.precone_deg == ref.precone_deg == 2.5      # -PreCone(1) = -(-2.5)
    assert rotor.tilt_deg == ref.tilt_deg == 5.0            # -ShftTilt = -(-5)


def test_traced_difference_hub_height_from_elastodyn_geometry():
    """ElastoDyn gives 90.0000034 m, the report (and the embedded rotor) 90 m."""
    rotor = from_openfast(FST).rotor
    expected = 87.6 + 1.96256 + 5.0191 * math.sin(math.radians(5.0))   # TowerHt + Twr2Shft + |OverHang| sin(tilt)
    assert rotor.hub_height == pytest.approx(expected, abs=1e-12)
    assert rotor.hub_height - load_rotor("nrel5mw").hub_height == pytest.approx(3.39e-6, abs=1e-8)


def test_traced_difference_tiprad_is_the_structural_tip():
    """ElastoDyn TipRad = 63 m; the AeroDyn blade ends at 1.5 + 61.4999 m (blade file comment)."""
    assert read_elastodyn(ED).tip_radius == 63.0
    source = from_openfast(FST)
    assert source.rotor.tip_radius == pytest.approx(62.9999, abs=1e-12)
    assert any("TipRad = 63" in note for note in source.notes)


# ---------------------------------------------------------------- set-up and fluid
def test_setup_and_fluid_fields_are_read():
    source = from_openfast(FST)
    assert source.drag_in_axial_induction is False and source.drag_in_tangential_induction is False
    assert source.tip_loss is True and source.hub_loss is True and source.tangential_induction is True
    assert source.air_density == 1.225 and source.kinematic_viscosity == 1.464e-05
    assert source.shear_exponent == 0.2 and source.reference_height == 90.0
    names = {p.name for p in source.files}
    assert {FST.name, ED.name, AD_GEN1.name, "NRELOffshrBsline5MW_AeroDyn_blade.dat",
            "NRELOffshrBsline5MW_InflowWind_12mps.dat", "DU21_A17.dat", "Cylinder1.dat"} <= names
    assert len(source.files) == 13 and all(p.is_file() for p in source.files)
    assert not any("ServoDyn" in n or "BeamDyn" in n for n in names)   # absent files never opened
    assert any("WindType = 3" in note for note in source.notes)


def test_default_air_density_comes_from_the_fst(deck):
    assert read_aerodyn_main(AD_GEN1).air_density is None               # the AeroDyn file says "default"
    set_value(deck, "AirDens", "1.1")
    set_value(deck, "KinVisc", "1.5E-05")
    source = from_openfast(deck)
    assert (source.air_density, source.kinematic_viscosity) == (1.1, 1.5e-05)


def test_default_air_density_without_fst_environment_is_unknown(deck):
    delete_lines(deck, ["AirDens", "KinVisc"])                           # an older .fst generation
    source = from_openfast(deck)
    assert source.air_density is None and source.kinematic_viscosity is None
    assert any('AirDens = "default"' in note and "not known" in note for note in source.notes)


def test_numeric_aerodyn_air_density_wins_over_the_fst(deck):
    set_value(deck.parent / AD_GEN1.name, "AirDens", "1.0")
    assert from_openfast(deck).air_density == 1.0


# ---------------------------------------------------------------- AeroDyn field generations
def test_both_aerodyn_field_generations_read_alike():
    old, new = read_aerodyn_main(AD_GEN1), read_aerodyn_main(AD_GEN2)
    assert (old.generation, new.generation) == (1, 2)
    for name in ("wake_model", "unsteady_airfoil", "tip_loss", "hub_loss", "tangential_induction",
                 "drag_in_axial_induction", "drag_in_tangential_induction", "air_density",
                 "kinematic_viscosity", "blade_file", "airfoil_files"):
        assert getattr(old, name) == getattr(new, name), name
    assert (old.wake_model, old.unsteady_airfoil) == (1, True)
    assert old.lines["WakeMod"] == line_of(AD_GEN1, "WakeMod")
    assert new.lines["Wake_Mod"] == line_of(AD_GEN2, "Wake_Mod")


def test_deck_with_the_openfast4_aerodyn_file(deck):
    set_value(deck, "AeroFile", f'"{AD_GEN2.name}"')
    source = from_openfast(deck)
    ref = from_openfast(FST)
    np.testing.assert_array_equal(source.rotor.r, ref.rotor.r)
    assert any(p.name == AD_GEN2.name for p in source.files)
    assert (source.drag_in_axial_induction, source.air_density) == (False, 1.225)


def test_aerodyn_without_wake_model_keyword_is_refused(tmp_path):
    bad = tmp_path / "ad.dat"
    bad.write_text(AD_GEN1.read_text().replace("WakeMod", "WakeModel"))
    with pytest.raises(InputError) as err:
        read_aerodyn_main(bad)
    assert err.value.source == str(bad) and err.value.field == "WakeMod"


def test_aerodyn_with_both_generations_is_refused(tmp_path):
    text = AD_GEN1.read_text().replace("TwrPotent", "TwrPotent\n          1   Wake_Mod  - new name", 1)
    bad = tmp_path / "ad.dat"
    bad.write_text(text)
    with pytest.raises(InputError) as err:
        read_aerodyn_main(bad)
    assert err.value.field == "Wake_Mod" and err.value.line == line_of(bad, "Wake_Mod")


# ---------------------------------------------------------------- sign conventions
def test_openfast_signs_are_converted(deck):
    ed = deck.parent / ED.name
    set_value(ed, "PreCone(1)", "-4")
    set_value(ed, "ShftTilt", "-6")
    rotor = from_openfast(deck).rotor
    assert (rotor.precone_deg, rotor.tilt_deg) == (4.0, 6.0)
    assert rotor.hub_height == pytest.approx(87.6 + 1.96256 + 5.0191 * math.sin(math.radians(6.0)), abs=1e-12)


def test_downwind_rotor_is_refused(deck):
    ed = deck.parent / ED.name
    set_value(ed, "OverHang", "5.0191")
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    assert (err.value.source, err.value.line, err.value.field) == (str(ed), line_of(ed, "OverHang"), "OverHang")


# ---------------------------------------------------------------- error paths of the files
def test_missing_referenced_file_names_the_referencing_file_and_key(deck):
    (deck.parent / ED.name).unlink()
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    assert (err.value.source, err.value.line, err.value.field) == (str(deck), line_of(deck, "EDFile"), "EDFile")
    assert ED.name in err.value.message


def test_missing_airfoil_names_the_aerodyn_file_and_afnames(deck):
    (deck.parent.parent / "5MW_Baseline" / "Airfoils" / "DU21_A17.dat").unlink()
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    ad = deck.parent / AD_GEN1.name
    du21_line = next(i for i, ln in enumerate(ad.read_text().splitlines(), 1) if "DU21_A17.dat" in ln)
    assert (err.value.source, err.value.line, err.value.field) == (str(ad), du21_line, "AFNames")


def test_malformed_elastodyn_value_names_file_and_line(deck):
    ed = deck.parent / ED.name
    set_value(ed, "HubRad", "1.5m")
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    assert (err.value.source, err.value.line, err.value.field) == (str(ed), line_of(ed, "HubRad"), "HubRad")
    assert "'1.5m'" in err.value.message


def test_elastodyn_keyword_missing_is_named(deck):
    ed = deck.parent / ED.name
    delete_lines(ed, ["Twr2Shft"])
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    assert (err.value.source, err.value.field) == (str(ed), "Twr2Shft")


def test_aerodyn_14_deck_is_refused(deck):
    set_value(deck, "CompAero", "1")
    with pytest.raises(InputError) as err:
        from_openfast(deck)
    assert (err.value.field, err.value.line) == ("CompAero", line_of(deck, "CompAero"))


# ---------------------------------------------------------------- the [rotor] table
@pytest.mark.parametrize("table, key", [
    ({"aerodyn_blade": "b.dat", "airfoils": ["a.dat"], **{k: v for k, v in NREL_SETUP.items() if k != "hub_radius"}},
     "rotor.hub_radius"),
    ({"aerodyn": "a.dat", **{k: v for k, v in NREL_SETUP.items() if k != "n_blades"}}, "rotor.n_blades"),
    ({"aerodyn": "a.dat", **{k: v for k, v in NREL_SETUP.items() if k != "tilt"}}, "rotor.tilt"),
])
def test_missing_key_when_the_files_lack_it(table, key):
    with pytest.raises(InputError) as err:
        rotor_from_table(table, WORKFLOW, ".")
    assert (err.value.source, err.value.field) == (WORKFLOW, key)
    assert "required" in err.value.message


@pytest.mark.parametrize("table, key", [
    ({"openfast": str(FST), "precone": 2.5}, "rotor.precone"),
    ({"name": "nrel5mw", "hub_height": 90.0}, "rotor.hub_height"),
])
def test_key_the_files_carry_is_refused(table, key):
    with pytest.raises(InputError) as err:
        rotor_from_table(table, WORKFLOW, ".")
    assert (err.value.source, err.value.field) == (WORKFLOW, key)


def test_two_sources_are_refused():
    with pytest.raises(InputError) as err:
        rotor_from_table({"name": "nrel5mw", "openfast": str(FST)}, WORKFLOW, ".")
    assert err.value.source == WORKFLOW and err.value.field == "rotor.openfast"
    assert "name and openfast" in err.value.message


def test_no_source_is_refused():
    with pytest.raises(InputError) as err:
        rotor_from_table(dict(NREL_SETUP), WORKFLOW, ".")
    assert err.value.field == "rotor"


def test_unknown_key_is_named_with_the_valid_ones():
    with pytest.raises(InputError) as err:
        rotor_from_table({"name": "nrel5mw", "hub_radus": 1.5}, WORKFLOW, ".")
    assert err.value.field == "rotor.hub_radus" and "valid keys: name, openfast" in err.value.message


def test_airfoils_without_blade_file_is_refused():
    with pytest.raises(InputError) as err:
        rotor_from_table({"airfoils": ["a.dat"], **NREL_SETUP}, WORKFLOW, ".")
    assert err.value.field == "rotor.aerodyn_blade"


@pytest.mark.parametrize("key, value", [("n_blades", 2.5), ("n_blades", True), ("hub_radius", -1.0),
                                        ("precone", "2.5"), ("hub_height", float("nan"))])
def test_wrong_value_types_are_refused(key, value):
    with pytest.raises(InputError) as err:
        rotor_from_table({"aerodyn": str(AD_GEN1), **{**NREL_SETUP, key: value}}, WORKFLOW, ".")
    assert err.value.field == f"rotor.{key}"


def test_table_paths_are_relative_to_base_dir_and_checked():
    source = rotor_from_table({"openfast": "openfast/5MW_Land_DLL_WTurb/5MW_Land_DLL_WTurb.fst"}, WORKFLOW, DATA)
    assert source.rotor.n_blades == 3
    with pytest.raises(InputError) as err:
        rotor_from_table({"openfast": "nowhere.fst"}, WORKFLOW, DATA)
    assert err.value.field == "rotor.openfast" and "nowhere.fst" in err.value.message


def test_aerodyn_main_and_blade_sources_with_typed_setup_give_the_deck_rotor():
    deck = from_openfast(FST).rotor
    main = rotor_from_table({"aerodyn": "openfast/5MW_Land_DLL_WTurb/" + AD_GEN2.name, **NREL_SETUP},
                            WORKFLOW, DATA)
    names = ["Cylinder1", "Cylinder2", "DU40_A17", "DU35_A17", "DU30_A17", "DU25_A17", "DU21_A17", "NACA64_A17"]
    blade = rotor_from_table({"aerodyn_blade": str(BASELINE / "NRELOffshrBsline5MW_AeroDyn_blade.dat"),
                              "airfoils": [str(BASELINE / "Airfoils" / f"{n}.dat") for n in names], **NREL_SETUP},
                             WORKFLOW, ".")
    for source in (main, blade):
        np.testing.assert_array_equal(source.rotor.r, deck.r)
        np.testing.assert_array_equal(source.rotor.airfoil_id, deck.airfoil_id)
        assert (source.rotor.precone_deg, source.rotor.tilt_deg, source.rotor.hub_height) == (2.5, 5.0, 90.0)
    assert main.drag_in_axial_induction is False and main.air_density is None   # "default", no .fst here
    assert blade.tip_loss is None and blade.air_density is None and len(blade.files) == 9


def test_embedded_and_windio_sources():
    embedded = rotor_from_table({"name": "NREL5MW"}, WORKFLOW, ".")
    assert embedded.rotor.name == "nrel5mw" and embedded.files == () and embedded.air_density is None
    windio = rotor_from_table({"windio": str(DATA_DIR / "iea15" / "IEA-15-240-RWT_windIO.yaml")}, WORKFLOW, ".")
    assert windio.rotor.n_blades == 3
    assert (windio.air_density, windio.shear_exponent) == (1.225, 0.12)          # environment section
    assert windio.kinematic_viscosity == pytest.approx(1.81e-5 / 1.225)
    with pytest.raises(InputError) as err:
        rotor_from_table({"name": "nrel6mw"}, WORKFLOW, ".")
    assert err.value.field == "rotor.name" and "nrel5mw" in err.value.message


# ---------------------------------------------------------------- nominal loads
def test_power_and_thrust_of_the_deck_match_the_embedded_rotor():
    """Same set-up (from the deck's files) on both rotors; only the traced 3.4 um hub-height
    difference separates them, so they agree far inside 0.5 %."""
    source = from_openfast(FST)
    settings = BemSettings(tip_loss=source.tip_loss, hub_loss=source.hub_loss,
                           drag_in_axial_induction=source.drag_in_axial_induction,
                           drag_in_tangential_induction=source.drag_in_tangential_induction,
                           wake_rotation=source.tangential_induction, shear_exponent=source.shear_exponent,
                           use_tilt=True)
    conditions = OperatingConditions(wind_speed=[6.0, 9.0, 11.4, 15.0, 20.0],
                                     rotor_speed=[7.2, 10.3, 12.1, 12.1, 12.1],
                                     pitch=[0.0, 0.0, 0.0, 10.45, 17.47], air_density=source.air_density)
    ours = BemModel(source.rotor, settings=settings, nuisance=()).evaluate(np.array([]), conditions)
    ref = BemModel(load_rotor("nrel5mw"), settings=settings, nuisance=()).evaluate(np.array([]), conditions)
    assert np.all(ours.status == Status.CONVERGED) and np.all(ref.status == Status.CONVERGED)
    assert np.all(ours.values > 0)
    np.testing.assert_allclose(ours.values, ref.values, rtol=5e-3)
