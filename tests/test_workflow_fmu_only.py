"""A third-party FMU calibrated from a workflow with no [rotor] and no [grid].

The FMU is the PythonFMU test rotor (tests/data/fmu/GenericRotor.py: km/h, rad/s, rad, kW,
kN, three scalar tuning parameters, no correction field). Its workflow names only [model]
(FMU + mapping), [measurements], [calibration] and [[stages]]; channels are checked against
the FMU's mapping, not the native BEM, so an output the BEM does not know is a channel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pythonfmu_export import export_fmu

from calib.calibration.result_files import load_result
from calib.cli import main
from calib.errors import InputError
from calib.fmu.model import FmuModel
from calib.measurements import synthesize
from calib.types import OperatingConditions
from calib.workflow import load_workflow, prepare

DATA = Path(__file__).parent / "data" / "fmu"
TRUTH = {"cp_gain": 1.08, "ct_gain": 0.94, "pitch_bias": 1.5}

pytestmark = pytest.mark.filterwarnings("ignore:.*InitialUnknowns")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The FMU, a mapping whose power output is called ``shaft_power``, and 18 measured points."""
    out = tmp_path_factory.mktemp("fmu-only")
    fmu = export_fmu("GenericRotor", out)
    mapping = (DATA / "generic_rotor_mapping.toml").read_text().replace(
        'power = { variable = "p_kw", unit = "kW", scale = 1000.0 }',
        'shaft_power = { variable = "p_kw", unit = "kW", scale = 1000.0, channel_unit = "W" }')
    assert "shaft_power" in mapping
    (out / "mapping.toml").write_text(mapping)
    model = FmuModel(fmu, out / "mapping.toml", ["shaft_power", "thrust"])
    wind, rpm, pitch = np.meshgrid([6.0, 8.0, 10.0], [12.0, 16.0], [0.0, 6.0, 12.0], indexing="ij")
    cond = OperatingConditions(wind.ravel(), rpm.ravel(), pitch.ravel())
    meas = synthesize(model, np.array(list(TRUTH.values())), cond,
                      relative_sigma={"shaft_power": 0.01, "thrust": 0.01}, seed=5)
    model.close()
    meas.write_csv(out / "field.csv")
    return out


def workflow(folder: Path, channels=("shaft_power", "thrust"), extra: str = "") -> Path:
    path = folder / "fmu_only.toml"
    path.write_text(f"""name = "generic FMU, no rotor"
[model]
kind = "fmu"
fmu = "GenericRotor.fmu"
mapping = "mapping.toml"
[measurements]
file = "field.csv"
[calibration]
noise = "known"
[[stages]]
name = "loads"
channels = {list(channels)!r}
retain = "all"
{extra}""".replace("'", '"'))
    return path


def test_fmu_workflow_needs_no_rotor_and_no_grid(campaign, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(workflow(campaign)), "--out", str(out), "-q"]) == 0
    res = load_result(out / "stage1_loads")
    assert res.estimate.status == "converged"
    for v in res.identifiability.verdicts:
        assert abs(v["value"] - TRUTH[v["name"]]) < 3 * v["std"], v
    report = (out / "report.html").read_text()
    assert "correction node" not in report and "Every parameter of the model" in report
    # the report leads with its decision, before the set-up table (issue 35, item 5)
    lead = report.index("<p class='decision'>")
    assert lead < report.index("<table") and "loads: the calibration ended converged; χ²/dof" in report[lead:]
    assert "3 identified" in report[lead:report.index("</p>", lead)]
    log_text = (out / "calib.log").read_text()
    assert "FMU GenericRotor.fmu" in log_text
    # two χ² of one run, read apart: the unit check's (with its allowance) and the calibration's (issue 35, item 3)
    assert "χ²/dof of the unit check: against the noise σ plus a 10% allowance" in log_text
    assert "against the stated σ (known): shaft_power " in log_text


def test_channels_are_checked_against_the_fmu(campaign):
    setup = prepare(load_workflow(workflow(campaign)))     # shaft_power: a channel the native BEM does not know
    assert setup.rotor is None and setup.grid(None) is None
    with pytest.raises(InputError, match="'power' is not provided by GenericRotor.fmu") as err:
        prepare(load_workflow(workflow(campaign, channels=("power",))))
    assert err.value.field == "stages.channels" and "shaft_power" in str(err.value)


def test_rotor_and_grid_stay_required_where_they_are_used(campaign, tmp_path):
    bem = tmp_path / "bem.toml"
    bem.write_text(workflow(campaign).read_text().replace('kind = "fmu"\nfmu = "GenericRotor.fmu"\n'
                                                          'mapping = "mapping.toml"\n', ""))
    with pytest.raises(InputError, match="missing required key 'rotor' .the native BEM's rotor"):
        load_workflow(bem)
    variant = tmp_path / "variant.toml"
    variant.write_text(workflow(campaign).read_text().replace('fmu = "GenericRotor.fmu"\nmapping = "mapping.toml"',
                                                              'variant = "A"') + '[rotor]\nname = "nrel5mw"\n')
    with pytest.raises(InputError, match="missing required key 'grid' .a bundled FMU variant"):
        load_workflow(variant)
    ignored = prepare(load_workflow(workflow(campaign, extra='[grid]\nalpha_nodes_deg = [0.0, 10.0]\n'
                                                            'eta_nodes = [0.5, 1.0]\n')))
    assert any("[grid] is not used" in note for note in ignored.notes)


def test_a_model_specific_channel_is_read_as_given_and_a_unit_on_it_refused(tmp_path):
    from calib.measurements import read_measurements

    path = tmp_path / "t.csv"
    path.write_text("wind_speed,rotor_speed,pitch,shaft_power,other\n8,12,0,1.5e6,3\n10,12,0,2.5e6,4\n")
    meas = read_measurements(path, ["shaft_power"])
    np.testing.assert_allclose(meas.channel("shaft_power"), [1.5e6, 2.5e6], rtol=0)
    assert any("read as given" in note and "shaft_power" in note for note in meas.notes)
    with pytest.raises(InputError, match="'power' is not in the file"):      # a known name is still required
        read_measurements(path, ["power"])
    path.write_text("wind_speed,rotor_speed,pitch,shaft_power [kW]\n8,12,0,1.5e3\n")
    with pytest.raises(InputError, match="cannot be converted") as err:
        read_measurements(path, ["shaft_power"])
    assert err.value.line == 1 and err.value.field == "shaft_power"


def test_calib_run_takes_the_noise_model_from_the_command_line(campaign, tmp_path, capsys):
    """Issue 35, item 4: a table without _sigma columns stops a workflow with the stated noise model;
    ``calib run --noise ml`` replaces the workflow's [calibration] noise and runs."""
    lines = [ln for ln in (campaign / "field.csv").read_text().splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    keep = [j for j, h in enumerate(head) if "_sigma" not in h]
    assert len(keep) < len(head)
    folder = tmp_path / "plain"
    folder.mkdir()
    for name in ("GenericRotor.fmu", "mapping.toml"):
        (folder / name).write_bytes((campaign / name).read_bytes())
    (folder / "field.csv").write_text("\n".join(",".join(r.split(",")[j] for j in keep) for r in lines) + "\n")
    wf = workflow(folder)
    assert main(["run", str(wf), "--out", str(tmp_path / "known"), "-q"]) == 2
    assert "sigma" in capsys.readouterr().err
    assert main(["run", str(wf), "--out", str(tmp_path / "ml"), "-q", "--noise", "ml"]) == 0
    res = load_result(tmp_path / "ml" / "stage1_loads")
    assert res.provenance.settings["noise"] == "ml" and res.estimate.status == "converged"
    assert "against the σ estimated with the fit (ml): shaft_power " in (tmp_path / "ml" / "calib.log").read_text()
    for v in res.identifiability.verdicts:
        assert abs(v["value"] - TRUTH[v["name"]]) < 3 * v["std"], v


def test_a_run_folder_given_for_a_result_lists_its_stage_folders(campaign, tmp_path):
    """'calib predict own ...' answered "own/result.json: result file not found" (issue 35): the run's
    folder holds stage folders, and the message names them."""
    out = tmp_path / "out"
    assert main(["run", str(workflow(campaign)), "--out", str(out), "-q"]) == 0
    with pytest.raises(InputError, match=r"give one of its stage folders, .*stage1_loads"):
        load_result(out)


def test_a_file_a_workflow_names_but_lacks_says_where_relative_paths_start(campaign, tmp_path):
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    wf = folder / "wf.toml"
    wf.write_text(workflow(campaign).read_text())      # names GenericRotor.fmu, mapping.toml, field.csv: not here
    with pytest.raises(InputError, match="relative to the workflow file's folder") as err:
        prepare(load_workflow(wf))
    assert err.value.field in ("model.fmu", "model.mapping", "measurements.file")
    (folder / "GenericRotor.fmu").write_bytes((campaign / "GenericRotor.fmu").read_bytes())
    (folder / "mapping.toml").write_bytes((campaign / "mapping.toml").read_bytes())
    with pytest.raises(InputError, match="measurement file not found: .*relative to the workflow file's folder") as err:
        from calib.workflow.setup import measurements_of

        measurements_of(load_workflow(wf), ["power"])
    assert err.value.field == "measurements.file"
