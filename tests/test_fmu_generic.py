"""A second exporter: a generic rotor FMU built by PythonFMU (FMI 2.0, Python inside, other
names and units, three scalar tuning parameters, no correction field, no azimuth output)
is calibrated through its mapping file like any model, and recovers its known parameters."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from pythonfmu_export import export_fmu

from calib.calibration import calibrate
from calib.fmu.model import FmuModel
from calib.measurements import synthesize
from calib.types import OperatingConditions

DATA = Path(__file__).parent / "data" / "fmu"


@pytest.fixture(scope="module")
def generic_fmu(tmp_path_factory):
    """Export the FMU with PythonFMU's command line (a missing PythonFMU fails the test)."""
    out = tmp_path_factory.mktemp("pythonfmu")
    return export_fmu("GenericRotor", out)


def test_generic_fmu_from_another_exporter_recovers_its_parameters(generic_fmu):
    # PythonFMU leaves ModelStructure/InitialUnknowns empty: fmpy's validation finding is a warning,
    # not a refusal (it does not prevent a correct simulation)
    with pytest.warns(UserWarning, match="InitialUnknowns"):
        model = FmuModel(generic_fmu, DATA / "generic_rotor_mapping.toml", ["power", "thrust"])
    assert not model.capabilities.correction_field and model.capabilities.name == "FmuModel"
    assert [q.name for q in model.parameters] == ["cp_gain", "ct_gain", "pitch_bias"]
    assert model.parameters[2].unit == "deg" and model.channels[0].unit == "W"
    wind, rpm, pitch = np.meshgrid([6.0, 8.0, 10.0], [12.0, 16.0], [0.0, 6.0, 12.0], indexing="ij")
    cond = OperatingConditions(wind.ravel(), rpm.ravel(), pitch.ravel())
    p_true = np.array([1.08, 0.94, 1.5])
    # package units in, package units out: the mapping's km/h, rad/s, rad, kW and kN are invisible
    ev = model.evaluate(p_true, cond)
    assert np.all(ev.status == 0), ev.messages
    lam = rpm.ravel() * np.pi / 30 * 40.0 / wind.ravel()
    b = np.radians(pitch.ravel() + p_true[2])
    q = 0.5 * 1.225 * np.pi * 40.0 ** 2
    power = q * wind.ravel() ** 3 * p_true[0] * 0.47 * np.exp(-0.5 * ((lam - 8) / 3) ** 2) * np.cos(b) ** 2
    np.testing.assert_allclose(ev.channel("power"), power, rtol=1e-4)     # settled lag: exp(-2 revs / 0.5 s)
    meas = synthesize(model, p_true, cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=5)
    res = calibrate(model, meas, retain="all", noise="known")
    model.close()
    assert res.estimate.status == "converged" and res.fit.failures["final"] == 0
    for v, truth, useful in zip(res.identifiability.verdicts, p_true, (0.025, 0.025, 1.0)):
        assert abs(v["value"] - truth) < 3 * v["std"], (v["name"], v["value"], truth, v["std"])
        assert v["std"] < useful, (v["name"], v["std"])     # informative: well inside the prior


def test_stated_priors_with_the_default_estimator_keep_the_parameters_independent(generic_fmu, tmp_path):
    # issue 34: a mapping that states prior_std for every parameter, with the default estimator (MAP),
    # gave two gains estimated identical, 7σ off, "converged": the prior was the outer product σσᵀ,
    # i.e. every stated parameter moving with every other
    mapping = (DATA / "generic_rotor_mapping.toml").read_text()
    assert mapping.count("scale = 0.05 }") == 2
    (tmp_path / "mapping.toml").write_text(mapping.replace("scale = 0.05 }", "scale = 0.05, prior_std = 0.1 }"))
    with pytest.warns(UserWarning, match="InitialUnknowns"):
        model = FmuModel(generic_fmu, tmp_path / "mapping.toml", ["power", "thrust"])
    assert np.isfinite([q.prior_std for q in model.parameters]).all()
    wind, rpm, pitch = np.meshgrid([6.0, 8.0, 10.0], [12.0, 16.0], [0.0, 6.0, 12.0], indexing="ij")
    cond = OperatingConditions(wind.ravel(), rpm.ravel(), pitch.ravel())
    p_true = np.array([1.08, 0.94, 1.5])
    meas = synthesize(model, p_true, cond, relative_sigma={"power": 0.01, "thrust": 0.01}, seed=5)
    res = calibrate(model, meas, noise="known")
    model.close()
    assert res.provenance.settings["estimator"] == "map" and res.estimate.status == "converged"
    values = [v["value"] for v in res.identifiability.verdicts]
    for v, truth in zip(res.identifiability.verdicts, p_true):
        assert abs(v["value"] - truth) < 3 * v["std"], (v["name"], v["value"], truth, v["std"])
    # the two gains are distinct: their difference is resolved, as the truth's 0.14 is
    assert abs(values[0] - values[1]) > 0.1, values
