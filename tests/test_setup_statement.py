"""The set-up in force: every value with where it came from (issue: a rotor file's tilt applied
silently to data from an axisymmetric rotor)."""

from pathlib import Path

import numpy as np
from test_workflow_setup import DECK, workflow

from calib.measurements import Measurements
from calib.report.setup_statement import statement, statement_html, statement_lines
from calib.types import OperatingConditions
from calib.workflow import load_workflow, prepare


def items_of(workflow, meas=None) -> dict:
    return {i.quantity: (i.value, i.origin) for i in statement(prepare(workflow), workflow, meas)}


def test_embedded_rotor_values_and_their_origins(tmp_path):
    cfg = load_workflow(workflow(tmp_path, extra="[model]\ntilt = 0.0\nnuisance = []\n[fluid]\ndensity = 1.1"))
    got = items_of(cfg)
    assert got["tilt"] == ("0 deg", "[model] tilt")
    assert got["precone"] == ("2.5 deg", "embedded rotor 'nrel5mw'")       # the rotor's own, not overridden
    assert got["shear exponent"] == ("0", "default")
    assert got["air density"] == ("1.1 kg/m^3", "[fluid] density")
    assert got["kinematic viscosity"][1].startswith("default")
    assert got["nuisance parameters"] == ("none", "[model] nuisance")
    assert got["noise model"] == ("known", "default")
    assert got["yaw"] == ("0 deg", "default")


def test_rotor_files_and_measurement_columns_are_named(tmp_path):
    cfg = load_workflow(workflow(tmp_path, rotor=f'openfast = "{DECK.as_posix()}"'))
    cond = OperatingConditions([8.0, 10.0], [9.0, 11.0], [0.0, 0.0], air_density=[1.2, 1.18], yaw=[0.0, 10.0])
    meas = Measurements(cond, ["power"], np.ones((2, 1)), metadata={"units": {"air_density": "kg/m^3",
                                                                            "yaw": "deg"}})
    got = items_of(cfg, meas)
    files = f"rotor files ({DECK.name})"
    assert got["tilt"] == ("5 deg", files) and got["shear exponent"] == ("0.2", files)
    assert got["air density"] == ("1.18 to 1.2 kg/m^3", "measurement column 'air_density'")
    assert got["yaw"] == ("0 to 10 deg", "measurement column 'yaw'")
    assert got["azimuth sectors"][0] == "4"                                 # tilted, sheared: not axisymmetric


def test_statement_lines_and_report_section(tmp_path):
    cfg = load_workflow(workflow(tmp_path))
    items = statement(prepare(cfg), cfg)
    lines = statement_lines(items)
    assert "tilt: 5 deg (embedded rotor 'nrel5mw')" in lines
    html = statement_html(items)
    assert "Set-up in force" in html and html.count("<tr>") == len(items) + 1


def test_calib_run_prints_and_reports_the_set_up(tmp_path):
    from calib.workflow import run_workflow

    path = Path(__file__).resolve().parents[1] / "workflows" / "wind_tunnel_hub_loads.toml"
    lines = []
    import calib.workflow.run as wf  # where the run says its lines
    original = wf.say
    try:
        wf.say = lambda log, line, progress=True: lines.append(line)
        run_workflow(path, tmp_path, progress=True, history=False)
    finally:
        wf.say = original
    stated = [line for line in lines if "set-up in force" in line]
    assert any("tilt:" in line for line in stated) and any("noise model:" in line for line in stated)
    assert "Set-up in force" in (tmp_path / "report.html").read_text()
