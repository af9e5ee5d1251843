"""The one configuration layer (calib.config): typed settings built from checked TOML tables."""

from __future__ import annotations

import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings
from calib.config import settings_from_table
from calib.diagnosis.in_workflow import diagnosis_settings
from calib.errors import InputError
from calib.models.from_config import BEM_KEYS, executor_from_table, model_from_workflow
from calib.workflow import CALIBRATION_KEYS
from calib.workflow.validation import ValidationSettings


def test_tables_become_typed_settings():
    cal = settings_from_table(CalibrationSettings, {"band_eta": [0.3, 0.7], "prior_correlation": 1, "sigma_bar": 2,
                                                    "force": True}, "calibration", "wf.toml", CALIBRATION_KEYS)
    assert cal.band_eta == (0.3, 0.7)                       # an array where the field holds a tuple
    assert isinstance(cal.prior_correlation, float) and cal.prior_correlation == 1.0
    assert cal.sigma_bar == 2 and isinstance(cal.sigma_bar, int)    # "auto" or a number: left as written
    bem = settings_from_table(BemSettings, {"polar_smoothing": [1, 2], "n_sectors": 4, "tilt": 5.0}, "model",
                              "wf.toml", BEM_KEYS)
    assert bem.polar_smoothing == (1, 2) and bem.n_sectors == 4
    val = ValidationSettings.from_table({"leave_out": "pitch", "confidence": 0.9, "channels": ["power"]}, "wf.toml")
    assert val == ValidationSettings("pitch", ("power",), 0.9)
    dset, channels = diagnosis_settings({"candidates": ["pitch_offset"], "significance": 0.05, "channels": ["power"]},
                                        "wf.toml")
    assert dset.candidates == ("pitch_offset",) and dset.significance == 0.05 and channels == ["power"]


@pytest.mark.parametrize("cls, schema, table, field, words", [
    (CalibrationSettings, CALIBRATION_KEYS, {"nosie": "ml"}, "calibration.nosie", "did you mean 'calibration.noise'"),
    (CalibrationSettings, CALIBRATION_KEYS, {"prior_sigma": "1"}, "calibration.prior_sigma", "must be a number"),
    (BemSettings, BEM_KEYS, {"n_sectors": 2.5}, "model.n_sectors", "must be an integer"),
])
def test_a_bad_table_is_refused_naming_file_and_key(cls, schema, table, field, words):
    section = field.split(".")[0] if "." in field else "model"
    with pytest.raises(InputError) as info:
        settings_from_table(cls, table, section, "wf.toml", schema)
    assert info.value.field == field
    assert words in str(info.value)


def test_the_native_bem_model_table_is_the_workflows():
    rotor = {"name": "nrel5mw"}
    m = model_from_workflow({"kind": "bem", "polar_smoothing": [1, 2], "tilt": 0.0, "tip_loss": False}, rotor,
                            ["power"], "wf.toml")
    assert m.settings.polar_smoothing == (1, 2) and m.settings.tip_loss is False
    assert m.rotor.tilt_deg == 0.0
    with pytest.raises(InputError) as info:
        model_from_workflow({"kind": "bem", "yaw": 5.0}, rotor, ["power"], "wf.toml")
    assert info.value.field == "model.yaw"
    with pytest.raises(InputError) as info:
        model_from_workflow({"kind": "bem", "tilt": 45.0}, rotor, ["power"], "wf.toml")
    assert info.value.field == "model.tilt"


@pytest.mark.parametrize("table, field, words", [
    ({"kind": "fmu", "parameters": [1]}, "model.parameters", "array of names"),
    ({"kind": "fmu", "timeout": "60"}, "model.timeout", "must be a number"),
    ({"kind": "fmu", "fmu": "rotor.fmu", "isolate": "yes"}, "model.isolate", "true/false"),
    ({"kind": "fmu", "mappping": "m.toml"}, "model.mappping", "did you mean 'model.mapping'"),
    ({"kind": "fmu"}, "model.fmu", "either fmu"),
    ({"kind": "fmu", "fmu": "rotor.fmu"}, "model.mapping", "needs mapping"),
])
def test_an_fmu_model_table_is_checked_before_anything_is_built(table, field, words):
    with pytest.raises(InputError) as info:
        model_from_workflow(table, {"name": "nrel5mw"}, ["power"], "wf.toml")
    assert info.value.field == field and words in str(info.value)


@pytest.mark.parametrize("table, field, words", [
    ({"kind": "process", "workers": 0}, "executor.workers", "must be >= 1"),
    ({"kind": "process", "address": "tcp://x:8786"}, "executor.address", "kind = \"dask\" only"),
    ({"kind": "mpi"}, "executor.kind", "valid: serial, process, dask"),
    ({"kind": "process", "worker": 2}, "executor.worker", "did you mean 'executor.workers'"),
])
def test_an_executor_table_is_checked(table, field, words):
    with pytest.raises(InputError) as info:
        executor_from_table(table, "wf.toml")
    assert info.value.field == field and words in str(info.value)


def test_an_executor_table_becomes_its_executor():
    from calib.executors.base import SerialExecutor

    ex = executor_from_table({"kind": "serial"}, "wf.toml")
    assert isinstance(ex, SerialExecutor) and ex.map(lambda x: 2 * x, [1, 2]) == [2, 4]
    ex.close()


def test_an_unknown_model_kind_gets_one_message_from_every_entry_point():
    """A recorded spec, a workflow's [model] table and a model built from a table refuse an unknown
    kind with the same words (calib.models.registry.model_kind), written once in the package."""
    from pathlib import Path

    from calib.models.registry import build_model
    from calib.workflow.schema import workflow_from_table

    words = r"unknown model kind 'ccblade'; valid kinds: bem, fmu"
    with pytest.raises(InputError, match=words) as spec:
        build_model({"kind": "ccblade"}, source="result.json: provenance.model_spec")
    with pytest.raises(InputError, match=words) as table:
        model_from_workflow({"kind": "ccblade"}, {"name": "nrel5mw"}, ["power"], "w.toml")
    with pytest.raises(InputError, match=words) as workflow:
        workflow_from_table({"name": "x", "model": {"kind": "ccblade"}, "stages": [{"name": "s", "channels": ["power"]}]},
                            "w.toml", ".")
    assert spec.value.field == "kind" and table.value.field == workflow.value.field == "model.kind"
    package = Path(__file__).resolve().parents[1] / "calib"
    assert sum(p.read_text().count('"unknown model kind') for p in package.rglob("*.py")) == 1


@pytest.mark.parametrize("entry", [(str, True), str, (str,)])
def test_a_schema_entry_that_is_not_a_key_is_a_programming_error(entry):
    """One schema form: check_table refuses a (type, required) pair or a bare type (TypeError, not the
    user's InputError), even for a table that would pass."""
    from calib.config import Key, check_table

    with pytest.raises(TypeError, match="calib.config.Key"):
        check_table({"name": "x"}, {"name": entry}, "", "wf.toml")
    assert check_table({"name": "x"}, {"name": Key(str, True)}, "", "wf.toml") == {"name": "x"}
