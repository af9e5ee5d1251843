"""Real data: the NREL Phase VI workflow (``workflows/phase_vi.toml``) on the measured sequence H.

One run of the workflow (diagnosis, two calibrations, leave-one-wind-speed-out
validation of each, figures, report) is shared by the tests; the assertions are the
acceptance of the real-data issue: the physics expects rotational augmentation (stall
delay) inboard; the calibrated model predicts the torque at held-out wind speeds better
than the nominal model, with the held-out measurements inside the 95 % prediction intervals
in at least five of six folds; with the pressure taps added more directions are informed
by the data and the field's directions localize in η.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from calib.calibration.result_files import load_result
from calib.workflow import run_workflow
from calib.workflow.validation import \
    INFORMED_LEVEL as INFORMED  # s_i >= this: informed by the data (σ_θ <= 2 prior units)

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW = ROOT / "workflows" / "phase_vi.toml"
HUB, TAPS = "stage1_hub_loads", "stage2_hub_loads_and_pressure_taps"
INBOARD_ETA = 0.45  # r/R of the inboard correction nodes


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("phase_vi")
    outcomes = run_workflow(WORKFLOW, out, progress=False)
    return out, {Path(o.out_dir).name: o for o in outcomes}


def test_the_measured_table_is_the_source_data():
    """The workflow's table carries the WDH values of the PROVENANCE anchors (not a model's output)."""
    with open(ROOT / "workflows" / "data" / "phase_vi_sequence_H.csv") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    by = {r["file_name"]: r for r in rows}
    assert float(by["h0700000"]["torque [N m]"]) == 789.8572 and float(by["h0700000"]["thrust [N]"]) == 1132.0692
    assert float(by["h2500000"]["torque [N m]"]) == 1580.4082 and float(by["h2500000"]["thrust [N]"]) == 4028.6306
    assert float(by["h1000000"]["cn@0.30"]) == 1.3413


def test_the_discrepancy_workflow_names_stall_delay(run):
    out, _ = run
    diag = json.loads((out / "diagnosis" / "diagnosis.json").read_text())
    assert diag["effect"] == "rotational_augmentation", diag["rounds"][0]["reason"]
    first = diag["rounds"][0]
    best = first["candidates"][0]
    assert best["name"].startswith("rotational_augmentation") and best["significant"]
    assert diag["with_effects"]["chi2_per_dof"] < diag["before"]["chi2_per_dof"]
    # the JSON result of each stage carries the named effect: in its model and in its statements
    for stage in (HUB, TAPS):
        res = load_result(out / stage)
        assert [e["name"] for e in res.provenance.model_spec["effects"]] == ["rotational_augmentation"]
        assert "named rotational_augmentation" in res.provenance.checks["diagnosis"]
        assert "stall_delay_strength" in [q["name"] for q in res.parameters]


@pytest.mark.parametrize("stage", [HUB, TAPS])
def test_leave_one_wind_speed_out_beats_the_nominal_model(run, stage):
    out, _ = run
    val = json.loads((out / stage / "validation.json").read_text())
    torque = next(s for s in val["summary"] if s["channel"] == "torque")
    assert torque["folds"] == 6 and torque["failed"] == 0
    assert torque["mean_abs_error_calibrated"] < torque["mean_abs_error_nominal"]
    assert torque["inside"] >= 5
    # the table in the report is the same one
    report = (out / "report.html").read_text()
    assert "Leave-one-out validation" in report and f"{torque['inside']} of 6 held-back" in report


def _field_modes(res):
    names = [q["name"] for q in res.parameters]
    field = np.array([n.startswith(("dCL", "dCD")) for n in names])
    eta = np.array([float(n.split("eta=")[1].rstrip("]")) if f else np.nan for n, f in zip(names, field)])
    modes = []
    for k in np.flatnonzero(res.identifiability.singular_values >= INFORMED):
        w = res.identifiability.V[:, k] ** 2
        share = w[field].sum() / w.sum()
        if share >= 0.5:   # a direction of the correction field (not of the effect or the pitch offset)
            modes.append(w[field & (eta <= INBOARD_ETA)].sum() / w[field].sum())
    return modes


def test_pressure_taps_inform_more_directions_and_localize_the_inboard_correction(run):
    out, _ = run
    hub, taps = load_result(out / HUB), load_result(out / TAPS)
    assert np.sum(taps.identifiability.singular_values >= INFORMED) > np.sum(hub.identifiability.singular_values >= INFORMED)
    assert np.sum(taps.identifiability.singular_values >= 1.0) > np.sum(hub.identifiability.singular_values >= 1.0)
    # the stall-delay strength: confounded from hub loads, identified with the taps. Under the MAP the
    # field's prior bounds the confounding, so σ moves little (0.12 -> 0.11 when written); what the taps
    # change is the information the strength shares with the correction field (0.76 -> 0.37)
    i = [q["name"] for q in hub.parameters].index("stall_delay_strength")
    assert hub.identifiability.verdicts[i]["verdict"] == "confounded"
    assert taps.identifiability.verdicts[i]["verdict"] == "identified"
    assert taps.uncertainty.std_p[i] < hub.uncertainty.std_p[i]
    assert (taps.identifiability.verdicts[i]["shared_information"]
            < 0.75 * hub.identifiability.verdicts[i]["shared_information"])
    # field directions informed by the hub loads sit outboard (torque arm); with the taps one
    # is concentrated on the inboard nodes, where the measured c_n exceeds the 2-D polar most
    assert max(_field_modes(hub), default=0.0) < 0.5
    assert max(_field_modes(taps)) >= 0.6


def test_the_report_shows_the_figures(run):
    out, _ = run
    for name in ("loads_vs_wind_speed.png", "cn_vs_wind_speed.png", "diagnosis/report.html",
                 "informed_eigenshapes_stage1.png", "informed_eigenshapes_stage2.png",
                 f"{HUB}/eigenshapes_lift.png", f"{TAPS}/eigenshapes_lift.png", f"{TAPS}/polars.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 1000, name


def test_the_diagnose_config_matches_the_workflow():
    """``calib diagnose --config workflows/diagnose/phase_vi.toml`` diagnoses the same problem."""
    from calib.tomlfile import read_toml

    wf = read_toml(WORKFLOW, "workflow")
    dg = read_toml(ROOT / "workflows" / "diagnose" / "phase_vi.toml", "config")
    for table in ("rotor", "grid", "calibration"):
        assert dg[table] == wf[table], table
