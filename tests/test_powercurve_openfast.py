"""Operating limits of the power curve's schedule from an OpenFAST deck (issue 41 item 3).

The deck is the OpenFAST r-test NREL 5-MW (tests/data/openfast, provenance there) with its ServoDyn
file and the lines of ROSCO's NREL-5MW DISCON.IN that the reader uses. Expected values are worked by
hand from the files' numbers (not from the code): rotor speed = generator speed / GBRatio (97).
"""

import shutil
from pathlib import Path

import numpy as np
import pytest

from calib.errors import InputError
from calib.powercurve.openfast_limits import read_discon, schedule_from_openfast

DECK = Path(__file__).parent / "data" / "openfast" / "5MW_Land_DLL_WTurb"
FST = DECK / "5MW_Land_DLL_WTurb.fst"


def test_rosco_limits_of_the_nrel_5mw_deck():
    lim = schedule_from_openfast(FST, rotor_radius=63.0)
    s = lim.schedule
    # VS_RefSpd 122.90967 rad/s / 97 = 1.267110 rad/s = 12.1000 rpm (Jonkman et al.'s rated rotor speed)
    assert s.max_rotor_speed == pytest.approx(122.90967 / 97 * 30 / np.pi, rel=1e-12)
    assert s.max_rotor_speed == pytest.approx(12.1, abs=1e-3)
    # VS_MinOMSpd 35.05042 rad/s / 97 = 0.361345 rad/s = 3.45059 rpm
    assert s.min_rotor_speed == pytest.approx(35.05042 / 97 * 30 / np.pi, rel=1e-12)
    # VS_RtPwr 5 MW electrical at 94.4 %: 5.2966 MW aerodynamic (TP-500-38060: 5.296610 MW mechanical)
    assert s.rated_power == pytest.approx(5e6 / 0.944, rel=1e-12)
    assert s.rated_power == pytest.approx(5296610.0, rel=1e-5)
    assert (s.design_tsr, s.fine_pitch, s.rotor_radius) == (7.59, 0.0, 63.0)
    assert s.generator_efficiency == pytest.approx(0.944, rel=1e-12)
    assert "line" in lim.sources["VS_RefSpd"] and "DISCON.IN" in lim.sources["VS_RefSpd"]
    assert "GBRatio = 97" in lim.sources["GBRatio"]


def _copy_deck(tmp_path):
    for p in (DECK, DECK.parent / "5MW_Baseline"):
        shutil.copytree(p, tmp_path / p.name)
    return tmp_path / DECK.name


def _edit(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))


def test_simple_variable_speed_control(tmp_path):
    deck = _copy_deck(tmp_path)
    sd = deck / "NRELOffshrBsline5MW_Onshore_ServoDyn.dat"
    _edit(sd, "          5   VSContrl", "          1   VSContrl")
    _edit(sd, "     9999.9   VS_RtGnSp", "    1173.7   VS_RtGnSp")
    _edit(sd, "     9999.9   VS_RtTq", "   43093.55   VS_RtTq")
    with pytest.raises(InputError, match="states no design tip-speed ratio"):
        schedule_from_openfast(deck / FST.name, 63.0)
    lim = schedule_from_openfast(deck / FST.name, 63.0, design_tsr=7.55)
    # 1173.7 rpm / 97 = 12.1 rpm; 1173.7 π/30 rad/s × 43093.55 N m = 5.2966 MW
    assert lim.schedule.max_rotor_speed == pytest.approx(1173.7 / 97, rel=1e-12)
    assert lim.schedule.rated_power == pytest.approx(1173.7 * np.pi / 30 * 43093.55, rel=1e-12)
    assert any("no minimum rotor speed" in n for n in lim.notes) and any("no fine pitch" in n for n in lim.notes)


@pytest.mark.parametrize("change, match", [
    (("ServoDyn.dat", "          5   VSContrl", "          3   VSContrl"), "VSContrl = 3"),
    (("ServoDyn.dat", '"DISCON.IN"    DLL_InFile', '"missing.IN"    DLL_InFile'), "missing.IN"),
    (("DISCON.IN", "122.9096700000      ! VS_RefSpd", "fast                ! VS_RefSpd"), "VS_RefSpd"),
    (("DISCON.IN", "122.9096700000      ! VS_RefSpd", "-122.90967          ! VS_RefSpd"), "VS_RefSpd"),
    (("DISCON.IN", "7.59                ! VS_TSRopt", ""), "VS_TSRopt not found"),
    (("DISCON.IN", "35.05042000000      ! VS_MinOMSpd", "135.05042          ! VS_MinOMSpd"), "cannot be followed"),
    (("ElastoDyn.dat", "         97   GBRatio", "       many   GBRatio"), "GBRatio"),
])
def test_bad_deck_is_a_clean_error_naming_file_and_key(tmp_path, change, match):
    deck = _copy_deck(tmp_path)
    suffix, old, new = change
    path = next(p for p in deck.iterdir() if p.name.endswith(suffix))
    _edit(path, old, new)
    with pytest.raises(InputError, match=match) as err:
        schedule_from_openfast(deck / FST.name, 63.0)
    assert path.name in str(err.value) or "VSContrl" in str(err.value)


def test_read_discon_keeps_line_numbers():
    v = read_discon(DECK / "DISCON.IN")
    text, line, name = v["vs_refspd"]
    assert (float(text), name) == (122.90967, "VS_RefSpd")
    assert (DECK / "DISCON.IN").read_text().splitlines()[line - 1].startswith("122.9096700000")


def test_cli_takes_the_schedule_from_the_deck(tmp_path):
    """``calib powercurve --schedule DECK.fst`` on a calibration of the embedded NREL 5-MW
    (workflows/blade_loads_localization.toml's first stage, hub loads)."""
    from calib.cli import main
    root = Path(__file__).resolve().parents[1]
    text = (root / "workflows" / "blade_loads_localization.toml").read_text()
    wf = tmp_path / "bl.toml"
    wf.write_text(text[:text.index('[[stages]]\nname = "hub and blade loads"')])
    out = tmp_path / "bl"
    assert main(["run", str(wf), "--out", str(out), "-q"]) == 0
    stage = next(out.glob("stage1*/result.json")).parent
    assert main(["powercurve", str(stage), "--schedule", str(FST), "--draws", "4", "--wind", "4:16:1",
                 "--out", str(tmp_path / "pc")]) == 0
    report = (tmp_path / "pc" / "report.md").read_text()
    assert "within 3.45059–12.1 rpm, fine pitch 0°" in report and "5.297 MW" in report
    # the same deck on the 10 m Phase VI rotor: 5.3 MW is above its Betz limit, refused
    from calib.powercurve import calibrated_power_curve, iec_bins
    from calib.calibration.result_files import load_result
    result = load_result(stage)
    lim = schedule_from_openfast(FST, rotor_radius=5.03)
    with pytest.raises(InputError, match="above what the rotor can produce"):
        calibrated_power_curve(result, iec_bins(4, 16, 1), lim.schedule, n_draws=2)
