"""The diagnosis knows where the campaign was (issue 37, item 2): in the field wind-tunnel
blockage is not a candidate; in a tunnel with a stated cross-section it is applied at the known
area ratio. Seeds 9600+ (used nowhere else)."""

import json

import numpy as np
import pytest

from calib.cli import main as cli_main
from calib.diagnosis.settings import DiagnosisSettings
from calib.effects import make_effect
from calib.errors import InputError
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from test_diagnosis import SETTINGS, campaign, hidden, run

#: Glauert's blockage hidden in the data: area ratio β = swept area / cross-section
BETA = 0.2


def test_a_known_area_ratio_gives_the_outputs_of_the_fitted_parameter_at_that_value():
    """``area_ratio`` applies the same correction as the free parameter at the same value, with no
    parameter left (the same formula, reached with a float instead of the parameter vector: equal to
    round-off)."""
    rotor = load_rotor("nrel5mw")
    cond = campaign(rotor)
    free = BemModel(rotor, None, ("power", "thrust"), SETTINGS, (), effects=[make_effect("wind_tunnel_blockage")])
    known = BemModel(rotor, None, ("power", "thrust"), SETTINGS, (),
                     effects=[make_effect("wind_tunnel_blockage", area_ratio=BETA)])
    assert len(known.parameters) == 0
    a = free.evaluate(np.array([BETA]), cond)
    b = known.evaluate(np.zeros(0), cond)
    assert a.ok.all() and b.ok.all()
    np.testing.assert_allclose(a.values, b.values, rtol=1e-12, atol=0)
    # and it is a correction: the nominal model gives other outputs
    nominal = BemModel(rotor, None, ("power", "thrust"), SETTINGS, ()).evaluate(np.zeros(0), cond)
    assert np.min(np.abs(b.values / nominal.values - 1)) > 1e-3


def test_a_field_campaign_never_names_wind_tunnel_blockage(tmp_path):
    """``calib diagnose --facility field`` on data that a tunnel's blockage made: blockage is not
    a candidate (the report says why), so the verdict is another effect or none, never blockage."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"wind_tunnel_blockage": {"blockage_area_ratio": BETA}}, campaign(rotor), 9600,
                  channels=("power", "thrust"))
    meas.write_csv(tmp_path / "data.csv")
    (tmp_path / "cfg.toml").write_text('[model]\nuse_tilt = false\n[diagnosis]\nrecalibrate = false\n'
                                       'candidates = ["wind_speed_scale", "pitch_offset"]\n')
    args = ["diagnose", "--rotor", "nrel5mw", "--data", str(tmp_path / "data.csv"), "--no-history"]
    # the same data with blockage a candidate: it is what the data show
    (tmp_path / "all.toml").write_text('[model]\nuse_tilt = false\n[diagnosis]\nrecalibrate = false\n'
                                       'candidates = ["wind_speed_scale", "pitch_offset", "wind_tunnel_blockage"]\n')
    assert cli_main(args + ["--config", str(tmp_path / "all.toml"), "--out", str(tmp_path / "tunnel")]) == 0
    tunnel = json.loads((tmp_path / "tunnel" / "diagnosis.json").read_text())
    assert "wind_tunnel_blockage" in tunnel["effects"], tunnel["rounds"][0]["reason"]
    # in the field: refused as a stated candidate, and left out of the default set
    assert cli_main(args + ["--config", str(tmp_path / "all.toml"), "--out", str(tmp_path / "x"),
                            "--facility", "field"]) == 2
    (tmp_path / "field.toml").write_text('[model]\nuse_tilt = false\n[diagnosis]\nrecalibrate = false\n'
                                         'max_effects = 1\n')
    assert cli_main(args + ["--config", str(tmp_path / "field.toml"), "--out", str(tmp_path / "field"),
                            "--facility", "field"]) == 0
    field = json.loads((tmp_path / "field" / "diagnosis.json").read_text())
    tried = {c["name"].split(":")[0] for r in field["rounds"] for c in r["candidates"]}
    assert "wind_tunnel_blockage" not in tried | set(field["effects"])
    assert len(tried) >= 5, tried
    assert any("wind_tunnel_blockage is not a candidate: a field campaign has no tunnel walls" in n
               for n in field["notes"]), field["notes"]
    report = (tmp_path / "field" / "report.html").read_text()
    assert "a field campaign has no tunnel walls" in report


def test_a_stated_cross_section_applies_the_blockage_it_implies():
    """In a tunnel of stated cross-section the nominal model carries Glauert's correction at the
    known area ratio: data made with that blockage leave nothing to name; stated wrong (half the
    blockage), the misfit remains."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"wind_tunnel_blockage": {"blockage_area_ratio": BETA}}, campaign(rotor), 9601,
                  channels=("power", "thrust"))
    right = run(meas, facility="wind_tunnel", cross_section=rotor.swept_area / BETA, recalibrate=False,
                candidates=("wind_speed_scale", "pitch_offset"))
    assert right.effect == "none", right.rounds[0]["reason"]
    assert right.before["chi2_per_dof"] < 1.5
    assert any("known area ratio 0.2 " in n for n in right.notes), right.notes
    assert any("wind_tunnel_blockage is not a candidate: its area ratio is known" in n for n in right.notes)
    wrong = run(meas, facility="wind_tunnel", cross_section=2 * rotor.swept_area / BETA, recalibrate=False,
                candidates=("wind_speed_scale", "pitch_offset"))
    assert wrong.before["chi2_per_dof"] > 5 * right.before["chi2_per_dof"]


@pytest.mark.parametrize("settings, field, message", [
    (dict(facility="lab"), "diagnosis.facility", "one of unstated, field, wind_tunnel, towing_tank"),
    (dict(facility="field", cross_section=900.0), "diagnosis.cross_section", "needs facility"),
    (dict(facility="wind_tunnel", cross_section=-1.0), "diagnosis.cross_section", "> 0"),
    (dict(facility="field", candidates=("wind_tunnel_blockage",)), "diagnosis.candidates", "no tunnel walls"),
    (dict(facility="towing_tank", cross_section=100.0, candidates=("wind_tunnel_blockage",)),
     "diagnosis.candidates", "known from the stated cross-section"),
])
def test_facility_settings_that_contradict_themselves_are_refused(settings, field, message):
    with pytest.raises(InputError, match=message) as err:
        DiagnosisSettings(**settings).validate("cfg.toml", "diagnosis.")
    assert err.value.field == field


def test_a_cross_section_smaller_than_the_rotor_is_refused():
    rotor = load_rotor("nrel5mw")
    meas = hidden({}, campaign(rotor), 9602, channels=("power",))
    with pytest.raises(InputError, match="does not fit a cross-section") as err:
        run(meas, facility="wind_tunnel", cross_section=0.5 * rotor.swept_area)
    assert err.value.field == "diagnosis.cross_section"
