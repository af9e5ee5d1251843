"""An FMU result's power curve (issue 41 item 5): the draws run through the FMU model's executor, one
evaluation per draw, and the simulations are counted and reported.

The FMU is the PythonFMU test rotor (tests/data/fmu/GenericRotor.py, three scalar tuning parameters)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pythonfmu_export import export_fmu

from calib.calibration.result_files import load_result
from calib.cli import main
from calib.fmu.model import FmuModel
from calib.measurements import synthesize
from calib.powercurve import FixedSpeed, calibrated_power_curve, iec_bins, posterior_draws
from calib.types import OperatingConditions

DATA = Path(__file__).parent / "data" / "fmu"
TRUTH = (1.08, 0.94, 1.5)

pytestmark = pytest.mark.filterwarnings("ignore:.*InitialUnknowns")


@pytest.fixture(scope="module")
def fmu_result(tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu-pc")
    fmu = export_fmu("GenericRotor", out)
    (out / "mapping.toml").write_text((DATA / "generic_rotor_mapping.toml").read_text())
    model = FmuModel(fmu, out / "mapping.toml", ["power", "thrust"])
    wind, rpm, pitch = np.meshgrid([6.0, 8.0, 10.0], [12.0, 16.0], [0.0, 6.0], indexing="ij")
    meas = synthesize(model, np.array(TRUTH), OperatingConditions(wind.ravel(), rpm.ravel(), pitch.ravel()),
                      relative_sigma={"power": 0.01, "thrust": 0.01}, seed=5)
    model.close()
    meas.write_csv(out / "field.csv")
    (out / "wf.toml").write_text('name = "fmu power curve"\n[model]\nkind = "fmu"\nfmu = "GenericRotor.fmu"\n'
                                 'mapping = "mapping.toml"\n[measurements]\nfile = "field.csv"\n[calibration]\n'
                                 'noise = "known"\n[[stages]]\nname = "loads"\nchannels = ["power", "thrust"]\n'
                                 'retain = "all"\n')
    assert main(["run", str(out / "wf.toml"), "--out", str(out / "run"), "-q"]) == 0
    return out / "run" / "stage1_loads"


def test_the_draws_run_through_the_fmu_and_are_counted(fmu_result):
    result = load_result(fmu_result)
    model = result.rebuild_model()
    v = iec_bins(6.0, 10.0, 1.0)
    schedule = FixedSpeed(14.0, 2.0)
    pc = calibrated_power_curve(result, v, schedule, n_draws=12, seed=4, model=model)
    assert pc.failed_draws == 0 and np.all(pc.central.ok)
    # every draw's and the central and nominal curves' bins were simulated: at least (12 + 2) × 5
    assert pc.simulations >= 14 * v.size
    assert any(f"the FMU ran {pc.simulations} simulations" in n for n in pc.notes)
    # a draw's curve is the FMU's own answer at that draw (another call, outside the power curve)
    D, _ = posterior_draws(result.estimate.p_hat, pc.cov, [q.lower for q in model.parameters],
                           [q.upper for q in model.parameters], 12, 4)
    ev = model.evaluate(D[3], OperatingConditions(v, np.full(v.size, 14.0), np.full(v.size, 2.0)))
    np.testing.assert_allclose(pc.draws["power"][3], ev.values[:, 0], rtol=1e-9)
    assert np.all(pc.draw_std("power") > 0)
    assert pc.delta_std == {} and any("no delta-method value" in n for n in pc.notes)


def test_the_command_reports_the_simulations_and_refuses_the_rotor_schedule(fmu_result, tmp_path, capsys):
    out = tmp_path / "pc"
    assert main(["powercurve", str(fmu_result), "--schedule", "fixed", "--rotor-speed", "14", "--pitch", "2",
                 "--wind", "6:10:1", "--draws", "8", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "The FMU ran" in printed and "simulations for this power curve" in printed
    assert "The FMU ran" in (out / "report.md").read_text()
    assert main(["powercurve", str(fmu_result), "--draws", "2", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--schedule" in err and "FMU" in err and "Traceback" not in err
