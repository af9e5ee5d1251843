"""Workflow set-up: one definition of every setting, rotors from the user's files, the fluid,
data-placed nodes, and settings errors that name the file and key before data is read."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings, Calibrator
from calib.calibration.result_files import load_result
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.measurements import read_measurements, synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, nominal_vector
from calib.workflow import CALIBRATION_KEYS, MODEL_KEYS, load_workflow, prepare, run_workflow

DECK = Path(__file__).resolve().parent / "data" / "openfast" / "5MW_Land_DLL_WTurb" / "5MW_Land_DLL_WTurb.fst"

BASE = """
name = "setup"
[rotor]
{rotor}
{extra}
[grid]
alpha_nodes_deg = {alpha}
eta_nodes = [0.3, 0.7, 1.0]
[measurements]
file = "data.csv"
[[stages]]
name = "hub"
channels = ["power", "thrust"]
"""


def workflow(tmp_path, rotor='name = "nrel5mw"', extra="", alpha="[-4.0, 4.0, 12.0]"):
    p = tmp_path / "wf.toml"
    p.write_text(BASE.format(rotor=rotor, extra=extra, alpha=alpha))
    return p


def test_api_and_toml_defaults_are_the_same(tmp_path):
    setup = prepare(load_workflow(workflow(tmp_path)))
    assert setup.settings == BemSettings()
    assert dataclasses.replace(setup.calibration, verbose=False) == CalibrationSettings()
    # every BemSettings / CalibrationSettings field has a workflow key of the same name
    assert {f.name for f in dataclasses.fields(BemSettings)} - set(MODEL_KEYS) == {"kinematic_viscosity"}
    assert {f.name for f in dataclasses.fields(CalibrationSettings)} - set(CALIBRATION_KEYS) == {"verbose"}


@pytest.mark.parametrize("extra, field", [
    ('[calibration]\nnoise = "loud"', "calibration.noise"),
    ('[calibration]\noptimizer = "newton"', "calibration.optimizer"),
    ('[calibration]\nsigma_bar = "small"', "calibration.sigma_bar"),
    ('[calibration]\nband_confidence = 1.5', "calibration.band_confidence"),
    ("[model]\ntilt = 95.0", "model.tilt"),
    ("[model]\nyaw = 120.0", "model.yaw"),
    ("[model]\nn_sectors = 0", "model.n_sectors"),
    ('[model]\nnuisance = ["yaw_offset"]', "model.nuisance"),
    ("[fluid]\ndensity = -1.0", "fluid.density"),
])
def test_settings_errors_name_file_and_key_before_reading_data(tmp_path, extra, field):
    # data.csv does not exist: the settings error must come first
    path = workflow(tmp_path, extra=extra)
    with pytest.raises(InputError) as err:
        run_workflow(path, tmp_path / "out", progress=False)
    assert err.value.field == field and err.value.source == str(path), str(err.value)


@pytest.mark.parametrize("eta", ["[0.0, 0.5, 1.0]", "[0.3, 0.7, 1.2]"])
def test_eta_nodes_outside_unit_interval_refused(tmp_path, eta):
    path = workflow(tmp_path)
    path.write_text(path.read_text().replace("eta_nodes = [0.3, 0.7, 1.0]", f"eta_nodes = {eta}"))
    with pytest.raises(InputError, match=r"\(0, 1\]") as err:
        prepare(load_workflow(path))
    assert err.value.field == "grid.eta_nodes"


def _nrel_csv(tmp_path, rotor, settings, density=1.225, rpm=10.0):
    model = BemModel(rotor, None, ("power", "thrust"), settings, ())
    tsr, pitch = np.meshgrid([5.0, 7.0, 9.0], [0.0, 3.0], indexing="ij")
    v = rpm * np.pi / 30 * rotor.rotor_radius / tsr.ravel()
    cond = OperatingConditions(v, np.full(v.size, rpm), pitch.ravel(), density)
    meas = synthesize(model, np.zeros(0), cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=8001)
    meas.write_csv(tmp_path / "data.csv")
    return cond


def test_openfast_deck_workflow_gives_the_embedded_rotor_nominal_outputs(tmp_path):
    """[rotor] openfast = r-test deck: the nominal outputs equal the embedded nrel5mw with the
    deck's set-up (AIDrag/TIDrag off, shear 0.2 at 90 m, tilt 5 deg) within 0.5 %."""
    deck_setup = BemSettings(drag_in_axial_induction=False, drag_in_tangential_induction=False,
                             shear_exponent=0.2, kinematic_viscosity=1.464e-5)
    embedded = load_rotor("nrel5mw")
    cond = _nrel_csv(tmp_path, embedded, deck_setup)
    path = workflow(tmp_path, rotor=f'openfast = "{DECK}"', extra='[calibration]\nnoise = "ml"')
    setup = prepare(load_workflow(path))
    assert setup.settings == deck_setup, setup.notes
    run_workflow(path, tmp_path / "out", progress=False)
    res = load_result(tmp_path / "out" / "stage1_hub")
    ref = BemModel(embedded, None, ("power", "thrust"), deck_setup, ()).evaluate(np.zeros(0), cond).values
    np.testing.assert_allclose(res.fit.model_before, ref, rtol=5e-3)
    # and the set-up matters at this level: the default (drag in the induction, no shear) differs
    plain = BemModel(embedded, None, ("power", "thrust"), BemSettings(), ()).evaluate(np.zeros(0), cond).values
    assert np.max(np.abs(plain / ref - 1)) > 5e-3


def test_water_rotor_follows_the_fluid(tmp_path):
    """A tidal-scale use of the Phase VI rotor in water (density 1000, ν = 1e-6): the workflow's
    nominal outputs equal the API's with the same fluid; the density comes from [fluid] when
    the table has no density column, and loads scale with it."""
    rotor = load_rotor("phase_vi")
    water = BemSettings(kinematic_viscosity=1e-6)
    cond = _nrel_csv(tmp_path, rotor, water, density=1000.0, rpm=20.0)
    text = (tmp_path / "data.csv").read_text().splitlines()
    # drop the air_density column: the workflow must take the density from [fluid]
    header = [h.strip() for h in text[[k for k, t in enumerate(text) if not t.startswith("#")][0]].split(",")]
    j = [k for k, h in enumerate(header) if h.startswith("air_density")][0]
    rows = [t if t.startswith("#") else ",".join(c for k, c in enumerate(t.split(",")) if k != j) for t in text]
    (tmp_path / "data.csv").write_text("\n".join(rows) + "\n")
    path = workflow(tmp_path, rotor='name = "phase_vi"', alpha='"auto"',
                    extra='[fluid]\ndensity = 1000.0\nkinematic_viscosity = 1e-6\n[calibration]\nnoise = "ml"')
    run_workflow(path, tmp_path / "out", progress=False)
    res = load_result(tmp_path / "out" / "stage1_hub")
    assert np.allclose(res.conditions["air_density"], 1000.0)
    api = BemModel(rotor, None, ("power", "thrust"), water, ()).evaluate(np.zeros(0), cond).values
    np.testing.assert_allclose(res.fit.model_before, api, rtol=1e-9)
    air = BemModel(rotor, None, ("power", "thrust"), BemSettings(), ()).evaluate(
        np.zeros(0), OperatingConditions(cond.wind_speed, cond.rotor_speed, cond.pitch, 1.225)).values
    np.testing.assert_allclose(api / air, 1000.0 / 1.225, rtol=1e-6)
    # alpha nodes placed by the data lie inside the reached range and are stated
    grid_alpha = sorted({p["alpha_deg"] for p in res.parameters if p["kind"] == "lift_correction"})
    assert len(grid_alpha) == 6 and grid_alpha[0] >= np.min(res.fit.alpha_seen) - 5


def test_workflow_and_api_give_identical_results(tmp_path):
    rotor = load_rotor("nrel5mw")
    settings = BemSettings()
    cond = _nrel_csv(tmp_path, rotor, settings)
    path = workflow(tmp_path, extra='[calibration]\nnoise = "ml"')
    run_workflow(path, tmp_path / "out", progress=False)
    wf = load_result(tmp_path / "out" / "stage1_hub")
    grid = CorrectionGrid([-4.0, 4.0, 12.0], [0.3, 0.7, 1.0])
    model = BemModel(rotor, grid, ("power", "thrust"), settings, ("pitch_offset",))
    meas = read_measurements(tmp_path / "data.csv", ["power", "thrust"])
    api = Calibrator(model, meas, CalibrationSettings(noise="ml")).run()
    np.testing.assert_array_equal(wf.estimate.p_hat, api.estimate.p_hat)
    np.testing.assert_array_equal(wf.uncertainty.cov_p, api.uncertainty.cov_p)
    assert np.allclose(cond.wind_speed, wf.conditions["wind_speed"])
    assert nominal_vector(model.parameters).size == wf.n_params


def test_shipped_own_turbine_workflow_runs(tmp_path, capsys):
    """The own-turbine example (README, docs/user_guide/own_turbine.md): OpenFAST deck + spreadsheet
    export, end to end."""
    wf = Path(__file__).resolve().parents[1] / "workflows" / "own_turbine.toml"
    outcomes = run_workflow(wf, tmp_path, progress=True)
    out = capsys.readouterr().out
    assert "delimiter: semicolon" in out and "timestamp, turbine_id" in out and "unit check: passed" in out
    res = outcomes[0].result
    assert res.estimate.status == "converged" and res.n_retained >= 1
    assert res.chi2_per_dof_before > 5 and res.chi2_per_dof_after < 1.5
    assert (tmp_path / "report.html").is_file()


def test_model_yaw_applies_to_points_without_a_yaw_column(tmp_path):
    rotor = load_rotor("nrel5mw")
    _nrel_csv(tmp_path, rotor, BemSettings())
    text = (tmp_path / "data.csv").read_text().splitlines()
    k = [i for i, t in enumerate(text) if not t.startswith("#")][0]
    header = text[k].split(",")
    j = [i for i, h in enumerate(header) if h.startswith("yaw")][0]
    rows = [t if t.startswith("#") else ",".join(c for i, c in enumerate(t.split(",")) if i != j) for t in text]
    (tmp_path / "data.csv").write_text("\n".join(rows) + "\n")
    run_workflow(workflow(tmp_path, extra='[model]\nyaw = 15.0\n[calibration]\nnoise = "ml"\nforce = true'),
                 tmp_path / "out", progress=False)
    res = load_result(tmp_path / "out" / "stage1_hub")
    assert np.allclose(res.conditions["yaw"], 15.0)


def test_alpha_nodes_placed_from_the_data_are_logged_not_printed_under_quiet(tmp_path, capsys):
    """`calib run --quiet` prints warnings and errors only: the set-up line that says where the
    α nodes went goes to the log file, not to the console."""
    from calib.logs import command_logging

    wf = Path(__file__).resolve().parents[1] / "workflows" / "own_turbine.toml"
    setup = prepare(load_workflow(wf))
    cond = OperatingConditions(np.array([6.0, 8.0, 10.0]), np.array([8.0, 9.5, 11.0]), np.zeros(3))
    with command_logging(tmp_path, quiet=True) as log_file:
        grid = setup.grid(cond, progress=True)
    assert grid.alpha_nodes_deg.size >= 2
    assert "alpha nodes from the data" not in capsys.readouterr().out
    assert "alpha nodes from the data" in Path(log_file).read_text()
