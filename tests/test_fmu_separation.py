"""An FMU diagnosis that cannot tell two candidates apart says so and names what would.

Rotor power and thrust cannot say which blade is pitched: a blade-1 and a blade-2 pitch offset
of the bundled FMU (variant A, quasi-steady, axisymmetric) fit them equally. The diagnosis
says ``ambiguous`` with both, and its separation probes, which ask the FMU for every steady
output its mapping maps, name a load on one blade (its root moment, its spanwise normal force).
"""

import json

from calib.diagnosis.command import run_diagnose
from test_resume import FMU_CONFIG, fmu_campaign

CHANNELS = ["power", "thrust"]


def test_blade_pitch_offsets_from_rotor_loads_are_ambiguous_and_a_blade_root_moment_separates_them(tmp_path):
    text = (FMU_CONFIG.replace('candidates = ["pitch_offset_blade1", "stall_delay_strength"]',
                               'candidates = ["pitch_offset_blade1", "pitch_offset_blade2"]')
            .replace('[executor]\nkind = "process"\nworkers = 2\n', ""))
    assert 'candidates = ["pitch_offset_blade1", "pitch_offset_blade2"]' in text and "[executor]" not in text
    config, data = fmu_campaign(tmp_path, text, CHANNELS, offset=2.0, relative_sigma=0.005, seed=9630)

    d = run_diagnose(None, str(data), str(tmp_path / "out"), str(config), printer=lambda line: None, history=False)
    rnd = d.rounds[0]
    assert d.effect == "ambiguous", rnd["reason"]
    assert set(rnd["ambiguous"]) == {"pitch_offset_blade1", "pitch_offset_blade2"}
    probes = rnd["separate"]["probes"]
    best = probes[0]
    # a load on one blade (root moment or spanwise normal force); since the probes keep to the campaign's rotor
    # speeds (an FMU states no operating limits), the best is the spanwise normal force near the tip
    assert best["channel"].startswith(("root_flap_moment", "root_edge_moment", "fn@")) and best["separation"] > 3, \
        probes
    assert "probes within the campaign's rotor speeds" in rnd["reason"]
    # already at a measured point: a load on one blade (root moment or spanwise normal force), which
    # the campaign did not measure
    here = next(p for p in probes if p["kind"] == "measured point, another channel")
    assert here["channel"].startswith(("root_", "fn@")) and here["separation"] > 3, probes
    assert "to tell them apart, measure " + best["channel"] in rnd["reason"]
    saved = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert saved["effect"] == "ambiguous" and saved["rounds"][0]["separate"]["probes"][0]["channel"] == best["channel"]
