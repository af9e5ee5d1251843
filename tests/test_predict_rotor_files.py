"""`calib predict` and `CalibrationResult.predict` rebuild the model from the result alone.

For every rotor source kind a tiny workflow is calibrated with its rotor files copied into a
temporary project; the files are then deleted and the result folder moved, and predictions
from another working directory must equal those made before (the result records the rotor as
data). Results without rotor data (older versions) fall back to the recorded files and refuse,
naming the file, when one is missing or changed.
"""

import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from floats import assert_same_numbers

from calib.calibration.result_files import load_result
from calib.cli import main as cli_main
from calib.errors import InputError
from calib.history import content_digest
from calib.models.registry import build_model, check_fmu_files
from calib.rotor.library import DATA_DIR, ROTORS, load_rotor
from calib.rotor.provenance import file_provenance
from calib.rotor.serialize import rotor_digest, rotor_from_dict, rotor_to_dict
from calib.rotor.sources import rotor_from_table
from calib.types import OperatingConditions

DATA = Path(__file__).parent / "data"
AIRFOILS = ["Cylinder1", "Cylinder2", "DU40_A17", "DU35_A17", "DU30_A17", "DU25_A17", "DU21_A17", "NACA64_A17"]
SETUP = 'hub_radius = 1.5\nprecone = 2.5\ntilt = 5.0\nhub_height = 90.0\nn_blades = 3\n'
BLADE_AIRFOIL = "rotor/5MW_Baseline/Airfoils/DU25_A17.dat"      # an airfoil the blade-file kind reads

#: kind -> (files to copy into the project's rotor/ folder, [rotor] table)
KINDS = {
    "name": ([], 'name = "nrel5mw"\n'),
    "aerodyn_blade": ([DATA / "openfast" / "5MW_Baseline"],
                      'aerodyn_blade = "rotor/5MW_Baseline/NRELOffshrBsline5MW_AeroDyn_blade.dat"\n'
                      'airfoils = [' + ", ".join(f'"rotor/5MW_Baseline/Airfoils/{n}.dat"' for n in AIRFOILS)
                      + ']\n' + SETUP),
    "aerodyn": ([DATA / "openfast" / "5MW_Baseline", DATA / "openfast" / "5MW_Land_DLL_WTurb"],
                'aerodyn = "rotor/5MW_Land_DLL_WTurb/NRELOffshrBsline5MW_Onshore_AeroDyn.dat"\n' + SETUP),
    "openfast": ([DATA / "openfast" / "5MW_Baseline", DATA / "openfast" / "5MW_Land_DLL_WTurb"],
                 'openfast = "rotor/5MW_Land_DLL_WTurb/5MW_Land_DLL_WTurb.fst"\n'),
    "windio": ([DATA_DIR / "iea3p4" / "IEA-3.4-130-RWT_windIO.yaml"], 'windio = "rotor/IEA-3.4-130-RWT_windIO.yaml"\n'),
}

WORKFLOW = """
name = "tiny"
[rotor]
{rotor}
[model]
use_tilt = false
[grid]
alpha_nodes_deg = [-4.0, 4.0, 12.0]
eta_nodes = [0.3, 0.7, 1.0]
[conditions]
tsr = [5.0, 7.0, 9.0]
pitch = [0.0, 3.0]
rotor_speed = 10.0
[truth]
[[truth.bumps]]
block = "lift"
amplitude = -0.1
alpha_deg = 6.0
alpha_width = 4.0
[noise]
relative = {{ power = 0.01, thrust = 0.01 }}
seed = 3
[[stages]]
name = "hub"
channels = ["power", "thrust"]
"""

# conditions between and beyond the calibration points
NEW = OperatingConditions(wind_speed=[6.0, 8.5, 11.0], rotor_speed=[9.0, 10.0, 11.0], pitch=[0.5, 1.5, 4.0])


def write_conditions(path: Path) -> Path:
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["wind_speed [m/s]", "rotor_speed [rpm]", "pitch [deg]"])
        for row in zip(NEW.wind_speed, NEW.rotor_speed, NEW.pitch):
            w.writerow([repr(float(x)) for x in row])
    return path


def read_prediction(path: Path) -> list[list[str]]:
    return [r for r in csv.reader(open(path)) if r and not r[0].startswith("#")]


def calibrate(root: Path, kind: str) -> dict:
    """Run the tiny workflow of ``kind`` in ``root/project``; returns the paths and the
    predictions at NEW made in place, before anything moves."""
    project = root / "project"
    (project / "rotor").mkdir(parents=True)
    files, table = KINDS[kind]
    for f in files:
        if f.is_dir():
            shutil.copytree(f, project / "rotor" / f.name)
        else:
            shutil.copy(f, project / "rotor" / f.name)
    (project / "wf.toml").write_text(WORKFLOW.format(rotor=table))
    here = os.getcwd()
    os.chdir(root)              # relative paths, as typed: the readers' provenance strings are relative too
    try:
        assert cli_main(["run", "project/wf.toml", "--out", "out", "-q", "--no-history"]) == 0
    finally:
        os.chdir(here)
    stage = root / "out" / "stage1_hub"
    cond = write_conditions(root / "new.csv")
    assert cli_main(["predict", str(stage), "--data", str(cond), "--out", str(root / "pred_before.csv")]) == 0
    before = load_result(stage).predict(NEW)
    return {"root": root, "project": project, "stage": stage, "conditions": cond, "kind": kind,
            "values": before.values, "std": before.std, "csv": read_prediction(root / "pred_before.csv")}


@pytest.fixture(scope="module")
def calibrations(tmp_path_factory):
    """kind -> its calibration, run once for the module (on first use)."""
    done = {}

    def get(kind):
        if kind not in done:
            done[kind] = calibrate(tmp_path_factory.mktemp(kind), kind)
        return done[kind]
    return get


@pytest.fixture(params=list(KINDS))
def run(request, calibrations):
    return calibrations(request.param)


@pytest.fixture
def blade_run(calibrations):
    return calibrations("aerodyn_blade")


def moved_copy(run: dict, dest: Path) -> Path:
    """A copy of the run's stage folder under ``dest``."""
    target = dest / "moved" / "stage"
    shutil.copytree(run["stage"], target)
    return target


def strip_rotor_data(stage: Path, keep_files: bool = True) -> None:
    """Make the result look written by an older version: no rotor data (and optionally no
    file provenance either)."""
    path = stage / "result.json"
    meta = json.loads(path.read_text())
    spec = meta["provenance"]["model_spec"]
    del spec["rotor_data"]
    if not keep_files:
        spec.pop("rotor_files", None)
        spec.pop("rotor_sha256", None)
    path.write_text(json.dumps(meta, indent=1))


# ----------------------------------------------------------------------------- every source kind
def test_result_predicts_after_its_rotor_files_are_gone_and_its_folder_moved(run, tmp_path, monkeypatch, capsys):
    project = run["project"]
    target = moved_copy(run, tmp_path)
    hidden = project.parent / "rotor_files_gone"
    (project / "rotor").rename(hidden)                      # the result must not need the rotor files
    try:
        check_moved_result(run, target, tmp_path, monkeypatch, capsys)
    finally:
        hidden.rename(project / "rotor")


def check_moved_result(run, target, tmp_path, monkeypatch, capsys):
    project = run["project"]
    spec = json.loads((target / "result.json").read_text())["provenance"]["model_spec"]
    assert spec["rotor_data"]["format"] == "calib.rotor/1"
    if run["kind"] != "name":                               # provenance: every file, absolute and relative, digest
        files = spec["rotor_files"]["files"]
        assert files and all(Path(f["path"]).is_absolute() and len(f["sha256"]) == 64 for f in files)
        assert all(f["relative"].startswith("rotor") for f in files)
        assert spec["rotor_files"]["workflow_dir"] == str(project.resolve())
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    capsys.readouterr()
    out = Path("pred.csv")
    code = cli_main(["predict", str(Path("..") / "moved" / "stage"), "--data", str(run["conditions"]),
                     "--out", str(out)])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "set-up recorded by the result" in printed.out and "from the result's recorded rotor data" in printed.out
    assert f"rotor {spec['rotor_data']['name']}" in printed.out and "nuisance pitch_offset" in printed.out
    assert "air density 1.225 kg/m^3" in printed.out
    assert read_prediction(out) == run["csv"]
    after = load_result(target).predict(NEW)
    np.testing.assert_allclose(after.values, run["values"], rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(after.std, run["std"], rtol=1e-12, atol=0.0)


def test_rebuilt_model_reproduces_the_values_the_run_computed(run):
    """The rebuilt model at p̂ and the calibration's own conditions gives the model values the
    run recorded with its model built from the files (an independent reference)."""
    res = load_result(run["stage"])
    pred = res.predict(OperatingConditions(**res.conditions))
    ok = res.fit.status_after == 0
    assert ok.any()
    np.testing.assert_allclose(pred.values[ok], res.fit.model_after[ok], rtol=1e-10, atol=0.0)


# ----------------------------------------------------------------------------- results without rotor data
def test_old_style_result_rebuilds_from_unchanged_files(blade_run, tmp_path, monkeypatch):
    target = moved_copy(blade_run, tmp_path)
    strip_rotor_data(target)
    monkeypatch.chdir(tmp_path)
    res = load_result(target)
    np.testing.assert_allclose(res.predict(NEW).values, blade_run["values"], rtol=1e-12, atol=0.0)


def predict_without(blade_run, tmp_path, capsys, missing: Path, keep_files: bool = True) -> tuple[int, str]:
    """``calib predict`` on an old-style copy of the result (no rotor data) while ``missing`` is
    away; (exit code, stderr)."""
    target = moved_copy(blade_run, tmp_path)
    strip_rotor_data(target, keep_files=keep_files)
    saved = missing.read_bytes()
    missing.unlink()
    try:
        code = cli_main(["predict", str(target), "--data", str(blade_run["conditions"]),
                         "--out", str(tmp_path / "p.csv")])
    finally:
        missing.write_bytes(saved)
    return code, capsys.readouterr().err


def test_old_style_result_with_a_missing_file_names_it(blade_run, tmp_path, capsys):
    airfoil = blade_run["project"] / BLADE_AIRFOIL
    code, err = predict_without(blade_run, tmp_path, capsys, airfoil)
    assert code == 2
    assert str(airfoil.resolve()) in err and "missing" in err and "Traceback" not in err
    assert "rotor.airfoils[5]" in err                                  # the key of the table that names it
    assert not (tmp_path / "p.csv").exists()


def test_old_style_result_without_digests_with_a_missing_file_names_it(blade_run, tmp_path, capsys):
    blade = blade_run["project"] / "rotor/5MW_Baseline/NRELOffshrBsline5MW_AeroDyn_blade.dat"
    code, err = predict_without(blade_run, tmp_path, capsys, blade, keep_files=False)
    assert code == 2 and str(blade.resolve()) in err and "missing" in err and "Traceback" not in err


def test_old_style_result_with_a_changed_file_names_it(blade_run, tmp_path, capsys):
    target = moved_copy(blade_run, tmp_path)
    strip_rotor_data(target)
    airfoil = blade_run["project"] / BLADE_AIRFOIL
    saved = airfoil.read_bytes()
    airfoil.write_bytes(saved.replace(b"0.", b"0.0", 1))          # one edit, still a valid file or not: refused
    try:
        code = cli_main(["predict", str(target), "--data", str(blade_run["conditions"]),
                         "--out", str(tmp_path / "p.csv")])
    finally:
        airfoil.write_bytes(saved)
    err = capsys.readouterr().err
    assert code == 2
    assert str(airfoil.resolve()) in err and "changed since the run" in err and "Traceback" not in err
    import hashlib
    old, new = hashlib.sha256(saved).hexdigest(), hashlib.sha256(saved.replace(b"0.", b"0.0", 1)).hexdigest()
    assert old[:12] in err and new[:12] in err                       # both digests, shortened


@pytest.mark.parametrize("layout", ["relative", "flat"])
def test_old_style_result_finds_files_copied_beside_it(blade_run, tmp_path, layout):
    """Files gone from their recorded paths are looked for in the result's folder, under their
    paths relative to the workflow or under their names (same bytes required)."""
    target = moved_copy(blade_run, tmp_path)
    strip_rotor_data(target)
    rotor_dir = blade_run["project"] / "rotor"
    if layout == "relative":
        shutil.copytree(rotor_dir, target / "rotor")
    else:
        for f in rotor_dir.rglob("*.dat"):
            shutil.copy(f, target / f.name)
    hidden = blade_run["project"] / "rotor_hidden"
    rotor_dir.rename(hidden)
    try:
        values = load_result(target).predict(NEW).values
    finally:
        hidden.rename(rotor_dir)
    np.testing.assert_allclose(values, blade_run["values"], rtol=1e-12, atol=0.0)


def test_changed_airfoil_behind_an_openfast_deck_is_named(tmp_path, capsys):
    """A file the deck leads to (not named in the [rotor] table) is checked too."""
    project = tmp_path / "project"
    shutil.copytree(DATA / "openfast", project / "rotor")
    table = {"openfast": str(project / "rotor/5MW_Land_DLL_WTurb/5MW_Land_DLL_WTurb.fst")}
    rsrc = rotor_from_table(table, "wf.toml", project)
    from calib.models.bem_model import BemModel
    spec = BemModel(rsrc.rotor, None, ("power",), nuisance=(), rotor_source=table,
                    rotor_files=file_provenance(rsrc.files, project)).spec()
    assert spec["rotor_files"]["all_files_read"] and len(spec["rotor_files"]["files"]) == len(rsrc.files)
    del spec["rotor_data"]
    cond = OperatingConditions([8.0], [10.0], [0.0])
    before = build_model(json.loads(json.dumps(spec))).evaluate(np.zeros(0), cond).values
    assert_same_numbers(before, BemModel(rsrc.rotor, None, ("power",), nuisance=()).evaluate(
        np.zeros(0), cond).values)
    airfoil = project / "rotor/5MW_Baseline/Airfoils/DU30_A17.dat"
    airfoil.write_bytes(airfoil.read_bytes() + b"\n")
    with pytest.raises(InputError) as err:
        build_model(spec, source="result.json: model_spec")
    assert str(airfoil.resolve()) in str(err.value) and "changed since the run" in str(err.value)


# ----------------------------------------------------------------------------- the recorded rotor
@pytest.mark.parametrize("make", [
    *[pytest.param(lambda n=n: load_rotor(n), id=n) for n in ROTORS],
    pytest.param(lambda: rotor_from_table({"openfast": str(DATA / "openfast/5MW_Land_DLL_WTurb/5MW_Land_DLL_WTurb.fst")},
                                          "wf", ".").rotor, id="openfast"),
    pytest.param(lambda: rotor_from_table({"windio": str(DATA_DIR / "iea15/IEA-15-240-RWT_windIO.yaml")},
                                          "wf", ".").rotor, id="windio"),
])
def test_rotor_round_trip_through_json_is_exact(make):
    rotor = make()
    back = rotor_from_dict(json.loads(json.dumps(rotor_to_dict(rotor), allow_nan=True)))
    assert content_digest(back) == content_digest(rotor) == rotor_digest(rotor)
    assert back.source == rotor.source and back.name == rotor.name
    for a, b in zip(rotor.airfoils, back.airfoils, strict=True):
        assert a.notes == b.notes
        for t, u in zip(a.tables, b.tables, strict=True):
            np.testing.assert_array_equal(t.cl, u.cl)     # exact by design: the digest check relies on it
            assert t.reynolds == u.reynolds or (np.isnan(t.reynolds) and np.isnan(u.reynolds))


def test_recorded_rotor_data_that_do_not_match_their_digest_are_refused():
    from calib.models.bem_model import BemModel
    spec = json.loads(json.dumps(BemModel(load_rotor("nrel5mw"), None, ("power",), nuisance=()).spec()))
    spec["rotor_data"]["chord"][5] *= 1.01
    with pytest.raises(InputError, match="do not match their recorded digest") as err:
        build_model(spec, source="result.json: model_spec")
    assert err.value.field == "rotor_data"
    del spec["rotor_data"]["chord"]
    with pytest.raises(InputError) as err:
        build_model(spec, source="result.json: model_spec")
    assert err.value.field == "rotor_data.chord"


def test_relative_rotor_path_without_a_folder_is_a_clean_error():
    with pytest.raises(InputError) as err:
        rotor_from_table({"windio": "turbine.yaml"}, "model spec", None)
    assert err.value.field == "rotor.windio" and "absolute" in err.value.message


# ----------------------------------------------------------------------------- FMU results
def test_fmu_files_are_checked_before_the_model_is_rebuilt(tmp_path):
    fmu, mapping = tmp_path / "m.fmu", tmp_path / "map.toml"
    fmu.write_bytes(b"fmu bytes")
    mapping.write_text("schema = 1\n")
    import hashlib
    spec = {"kind": "fmu", "fmu": str(fmu), "fmu_sha256": hashlib.sha256(b"fmu bytes").hexdigest(),
            "mapping": str(mapping), "mapping_sha256": hashlib.sha256(b"schema = 1\n").hexdigest()}
    check_fmu_files(spec, tmp_path)                                    # unchanged: passes
    fmu.write_bytes(b"other bytes")
    with pytest.raises(InputError, match="changed since the run") as err:
        build_model(spec, tmp_path, "result.json: model_spec")
    assert str(fmu) in str(err.value) and err.value.field == "fmu"
    fmu.unlink()
    with pytest.raises(InputError, match="missing") as err:
        build_model(spec, tmp_path, "result.json: model_spec")
    assert str(fmu) in str(err.value)
    check_fmu_files({**spec, "build": {"variant": "A"}}, tmp_path)     # a bundled variant is built again
    fmu.write_bytes(b"rebuilt bytes")
    check_fmu_files({**spec, "build": {"variant": "A"}}, tmp_path)     # ... by another compiler, perhaps
    fmu.write_bytes(b"fmu bytes")
    mapping.write_text("schema = 2\n")
    with pytest.raises(InputError, match="changed since the run") as err:
        build_model(spec, tmp_path, "result.json: model_spec")
    assert err.value.field == "mapping"
    mapping.write_text("schema = 1\n")
    fmu.write_bytes(b"fmu bytes")
    mapping.unlink()
    with pytest.raises(InputError, match="missing") as err:
        build_model(spec, tmp_path, "result.json: model_spec")
    assert str(mapping) in str(err.value) and err.value.field == "mapping"


def test_prediction_without_a_density_column_takes_the_calibrations(tmp_path):
    """A water rotor calibrated at 1000 kg/m^3 is not predicted in air because the new table
    has no air_density column; a column in the table wins."""
    from calib.calibration.predict_command import calibration_fluid
    from calib.measurements import read_measurements

    path = tmp_path / "new.csv"
    path.write_text("wind_speed,rotor_speed,pitch\n2.0,20,0\n2.5,20,0\n")
    lines = []
    meas = calibration_fluid(read_measurements(path, None, allow_no_channels=True),
                             {"air_density": [1000.0, 1000.0]}, lines.append)
    assert_same_numbers(meas.conditions.air_density, [1000.0, 1000.0])
    assert "the calibration's 1000 kg/m^3 used" in lines[0]
    path.write_text("wind_speed,rotor_speed,pitch,air_density\n2.0,20,0,998\n")
    own = calibration_fluid(read_measurements(path, None, allow_no_channels=True), {"air_density": [1000.0]}, print)
    assert_same_numbers(own.conditions.air_density, [998.0])
    path.write_text("wind_speed,rotor_speed,pitch\n8,12,0\n")         # several densities recorded: no guess
    mixed = calibration_fluid(read_measurements(path, None, allow_no_channels=True), {"air_density": [1.2, 1.22]},
                              print)
    assert_same_numbers(mixed.conditions.air_density, [1.225])
