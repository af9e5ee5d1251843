"""Workflow TOML files: schema errors name file and key; the method's two studies run."""

import json
import re
from pathlib import Path

import numpy as np
import pytest

from calib.calibration.result_files import load_result
from calib.cli import main as cli_main
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.workflow import load_workflow, run_workflow, smooth_field

WORKFLOWS = Path(__file__).resolve().parents[1] / "workflows"

SMALL = """
name = "small"
[rotor]
name = "nrel5mw"
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
relative = { power = 0.01, thrust = 0.01 }
seed = 3
[[stages]]
name = "hub"
channels = ["power", "thrust"]
"""


def write(tmp_path, text):
    p = tmp_path / "wf.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize("edit, field, words", [
    (("[grid]", "[grid]\nalpha_nodes = [1.0]"), "grid.alpha_nodes",
     "(did you mean 'grid.n_alpha_nodes' or 'grid.alpha_nodes_deg'?)"),
    (("[noise]", "[calibration]\nestimater = \"map\"\n[noise]"), "calibration.estimater",
     "(did you mean 'calibration.estimator'?)"),
    (('name = "small"', 'name = "small"\noptimiser = "x"'), "optimiser", "unknown key"),
    (("rotor_speed = 10.0", 'rotor_speed = "fast"'), "conditions.rotor_speed", "must be a number"),
    (("seed = 3", "seed = 3.5"), "noise.seed", "must be an integer"),
    (("use_tilt = false", "use_tilt = 1"), "model.use_tilt", "must be true/false"),
    (('block = "lift"', 'block = "moment"'), "truth.bumps[0].block", "'lift' or 'drag'"),
    (('[[stages]]\nname = "hub"\n', '[[stages]]\n'), "stages[0].name", "missing required key"),
])
def test_schema_errors_name_file_and_key(tmp_path, edit, field, words):
    path = write(tmp_path, SMALL.replace(*edit))
    with pytest.raises(InputError) as err:
        load_workflow(path)
    assert err.value.field == field
    assert str(path) in str(err.value) and words in str(err.value)


@pytest.mark.parametrize("edit, field, words", [
    (("alpha_width = 4.0", "alpha_width = -4.0"), "truth.bumps[0].alpha_width", "must be > 0, got -4.0"),
    (("use_tilt = false", "use_tilt = false\nyaw = 95.0"), "model.yaw", "within ±90, got 95.0"),
    (("use_tilt = false", 'use_tilt = false\nnuisance = ["yaw_offset"]'), "model.nuisance", "'yaw_offset' is not one"),
    (("[grid]\nalpha_nodes_deg = [-4.0, 4.0, 12.0]", '[grid]\nalpha_nodes_deg = "automatic"'), "grid.alpha_nodes_deg",
     'or "auto"'),
    (("rotor_speed = 10.0", "rotor_speed = 10.0\nyaw = 5.0\nair_density = 0.0"), "conditions.air_density",
     "must be > 0"),
    (("tsr = [5.0, 7.0, 9.0]", "tsr = [5.0, -7.0]"), "conditions.tsr", "tip-speed ratios must be > 0"),
    (("seed = 3", 'seed = 3\n[calibration]\nnoise = "loud"'), "calibration.noise", "unknown noise mode"),
    (('name = "hub"', 'name = "hub"\nretain = "some"'), "stages[0].retain", "must be one of threshold, all"),
])
def test_value_rules_run_once_at_load(tmp_path, edit, field, words):
    """A rule on a value is the key's (or its section's): it fails when the file is loaded, naming the file and
    the key path, before any rotor, model or data is read."""
    path = write(tmp_path, SMALL.replace(*edit))
    with pytest.raises(InputError) as err:
        load_workflow(path)
    assert err.value.field == field and err.value.source == str(path), str(err.value)
    assert words in str(err.value)


def test_a_loaded_workflow_is_typed_and_frozen(tmp_path):
    import dataclasses

    workflow = load_workflow(write(tmp_path, SMALL))
    assert workflow.name == "small" and workflow.source == str(tmp_path / "wf.toml")
    assert workflow.base_dir == str(tmp_path)
    assert workflow.stages[0].channels == ("power", "thrust") and workflow.truth.bumps[0].block == "lift"
    assert workflow.model.nuisance == ("pitch_offset",) and workflow.model.options == {"use_tilt": False}
    assert workflow.calibration.settings.noise == "known" and workflow.calibration.force is False
    with pytest.raises(dataclasses.FrozenInstanceError):
        workflow.name = "other"
    with pytest.raises(dataclasses.FrozenInstanceError):
        workflow.grid.eta_nodes = (0.5, 1.0)
    with pytest.raises(TypeError):
        workflow["stages"]       # the dict of before: no item access


def test_toml_syntax_error_gives_line_and_column(tmp_path):
    path = write(tmp_path, SMALL.replace("seed = 3", "seed = = 3"))
    with pytest.raises(InputError, match=r"not valid TOML.*line \d+, column \d+"):
        load_workflow(path)


def test_measurement_source_must_be_one_of_file_or_synthetic(tmp_path):
    path = write(tmp_path, SMALL + '\n[measurements]\nfile = "x.csv"\n')
    with pytest.raises(InputError, match="either"):
        load_workflow(path)


def test_cli_reports_errors_without_traceback(tmp_path, capsys):
    path = write(tmp_path, SMALL.replace("[grid]", "[grid]\nspacing = 2"))
    assert cli_main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "grid.spacing" in err and "Traceback" not in err


def test_small_workflow_writes_results_figures_and_report(tmp_path):
    out = tmp_path / "out"
    outcomes = run_workflow(write(tmp_path, SMALL), out, progress=False)
    stage_dir = outcomes[0].out_dir
    for name in ("result.json", "result.npz", "singular_values.png",
                 "eigenshapes_lift.png", "fit.png", "polars.png", "correlation.png"):
        assert (stage_dir / name).is_file(), name
    html = (out / "report.html").read_text()
    assert "data:image/png;base64," in html
    assert "χ²/dof" in html and "identified" in html
    back = load_result(stage_dir)
    np.testing.assert_allclose(back.estimate.p_hat, outcomes[0].result.estimate.p_hat)
    meta = json.loads((stage_dir / "result.json").read_text())
    assert "numpy" in meta["provenance"]["versions"]
    assert (out / "measurements.csv").is_file()


def test_shipped_workflows_validate():
    for path in sorted(WORKFLOWS.glob("*.toml")):
        workflow = load_workflow(path)
        assert workflow.stages


def test_the_bundled_fmu_workflow_runs_as_the_readme_says(tmp_path):
    """README's FMU job: `calib run workflows/bundled_fmu.toml` calibrates the bundled FMU (built from C
    source on first use) to data of the native BEM, a model of another code path, and its bands cover
    the known truth."""
    [stage] = run_workflow(WORKFLOWS / "bundled_fmu.toml", tmp_path, progress=False)
    res = stage.result
    assert res.estimate.status == "converged" and res.fit.failures["total_failed_point_evaluations"] == 0
    assert res.fit.chi2_before / res.dof > 5 and res.fit.chi2_after / res.dof < 1.5
    coverage = res.provenance.checks["coverage of the known truth"]
    lift, drag = (float(x) for x in re.findall(r"at ([0-9.]+) %", coverage))
    assert lift >= 90 and drag >= 90, coverage


def test_wind_tunnel_study_improves_fit_from_hub_loads(tmp_path):
    [stage] = run_workflow(WORKFLOWS / "wind_tunnel_hub_loads.toml", tmp_path, progress=False)
    res = stage.result
    assert res.estimate.status == "converged"
    assert res.fit.chi2_before / res.dof > 50            # nominal polars substantially wrong
    assert res.fit.chi2_after / res.dof < 2.0            # truth not in the span: close to, not at, 1
    assert 0 < res.n_retained < res.n_params         # hub loads identify only some combinations


def test_blade_loads_localize_the_correction(tmp_path):
    hub, blade = run_workflow(WORKFLOWS / "blade_loads_localization.toml", tmp_path, progress=False)
    assert blade.result.n_retained > hub.result.n_retained
    workflow = load_workflow(WORKFLOWS / "blade_loads_localization.toml")
    grid = CorrectionGrid(workflow.grid.alpha_nodes_deg, workflow.grid.eta_nodes)
    alpha = np.linspace(3.0, 11.0, 9)

    def lift_error(res, eta):
        est, _, _, _ = grid.evaluate(res.estimate.p_hat[:grid.n_params], alpha, np.full(alpha.size, eta))
        truth, _ = smooth_field(workflow.truth.bumps, alpha, np.full(alpha.size, eta))
        return est, truth

    # inside the DU25 span range: blade sensors recover the lift loss, hub loads smear it out
    est_blade, truth = lift_error(blade.result, 0.42)
    est_hub, _ = lift_error(hub.result, 0.42)
    err_blade, err_hub = (float(np.sqrt(np.mean((e - truth) ** 2))) for e in (est_blade, est_hub))
    print(f"lift error at η 0.42, RMS over α 3–11°: blade {err_blade:.4f}, hub {err_hub:.4f}, "
          f"truth {np.sqrt(np.mean(truth ** 2)):.4f}")
    assert err_blade < 0.4 * np.sqrt(np.mean(truth ** 2))
    assert err_hub > 0.4 * np.sqrt(np.mean(truth ** 2)) and err_blade < 0.5 * err_hub
    # outboard, where the truth is zero, the blade-load estimate stays small
    est_out, truth_out = lift_error(blade.result, 0.8)
    assert np.abs(truth_out).max() < 1e-6
    assert np.abs(est_out).max() < 0.25 * np.abs(truth).max()
    assert (tmp_path / "singular_value_spectra.png").is_file()
