"""Results written by earlier versions load into the nested result and predict (tests/data/results)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from calib.calibration.result_files import load_result, migrate_v2
from calib.calibration.result_parts import ARRAY_FIELDS
from calib.errors import InputError
from calib.types import OperatingConditions

OLD = Path(__file__).parent / "data" / "results" / "own_turbine_c519001"


def test_a_result_written_before_the_parts_loads_into_them():
    res = load_result(OLD)
    # exact: the loader hands over the bytes it read, no arithmetic in between (any CPU)
    with np.load(OLD / "result.npz") as z:
        np.testing.assert_array_equal(res.estimate.p_hat, z["p_hat"])
        np.testing.assert_array_equal(res.uncertainty.cov_p, z["cov_p"])
        np.testing.assert_array_equal(res.fit.model_after, z["model_after"])
    with pytest.raises(AttributeError, match=r"it is result\.estimate\.p_hat"):
        res.p_hat                                      # no flat names: the error names the part
    assert res.identifiability.retained.dtype == bool and res.fit.multiple_roots.dtype == bool
    assert res.provenance.model_spec and res.name == "field loads"
    assert res.uncertainty.gain.size and res.estimator == "map"
    doc = res.to_json_dict()
    assert doc["schema_version"] == 3 and "p_hat" not in doc and "p_hat" not in doc["estimate"]   # arrays: npz
    assert doc["estimate"]["status"] == res.estimate.status and doc["provenance"]["model_spec"]


def test_a_schema_2_result_saved_again_is_schema_3_with_the_same_content(tmp_path):
    old = load_result(OLD)
    old.save(tmp_path)
    assert json.loads((tmp_path / "result.json").read_text())["schema_version"] == 3
    with np.load(tmp_path / "result.npz") as z:
        assert "estimate.p_hat" in z.files and "p_hat" not in z.files
    new = load_result(tmp_path)
    # exact: the migration and the new files move the stored bytes, no arithmetic in between
    for part, name in ARRAY_FIELDS:
        np.testing.assert_array_equal(np.asarray(getattr(getattr(new, part), name)),
                                      np.asarray(getattr(getattr(old, part), name)), err_msg=f"{part}.{name}")
    assert new.to_json_dict() == old.to_json_dict()


def test_a_result_written_before_the_parts_rebuilds_its_model_and_predicts_what_it_recorded():
    res = load_result(OLD)
    pred = res.predict(OperatingConditions(**res.conditions))
    ok = res.fit.status_after == 0
    assert ok.all() and (pred.status == 0).all()
    # the model rebuilt by this version reproduces the outputs the old run recorded at its estimate
    np.testing.assert_allclose(pred.values, res.fit.model_after, rtol=1e-9)
    assert np.all(pred.std > 0)


def test_a_result_of_another_schema_is_refused_naming_the_version(tmp_path):
    res = load_result(OLD)
    res.save(tmp_path)
    text = (tmp_path / "result.json").read_text().replace('"schema_version": 3', '"schema_version": 1')
    (tmp_path / "result.json").write_text(text)
    with pytest.raises(InputError, match="unsupported result schema 1, expected 3"):
        load_result(tmp_path)


def test_the_parts_are_the_api_and_replace_copies():
    res = load_result(OLD)
    res.provenance.checks = {"note": "x"}
    assert res.provenance.checks == {"note": "x"}
    other = res.replace(estimate=dataclasses.replace(res.estimate, p_hat=res.estimate.p_hat + 1.0), name="moved")
    assert other.name == "moved" and np.allclose(other.estimate.p_hat, res.estimate.p_hat + 1.0)
    assert other.estimate is not res.estimate and res.name == "field loads"
    other.estimate.p_hat = np.zeros_like(res.estimate.p_hat)                    # the copy's part, not the original's
    assert np.any(res.estimate.p_hat != 0)
    fit = res.fit
    assert res.replace(fit=dataclasses.replace(fit, chi2_after=1.0)).fit.chi2_after == 1.0 and fit.chi2_after != 1.0
    with pytest.raises(AttributeError, match="no attribute 'p_hut'"):
        res.p_hut
    import pickle

    back = pickle.loads(pickle.dumps(res))      # (executors pickle what they return)
    np.testing.assert_array_equal(back.estimate.p_hat, res.estimate.p_hat)      # exact: pickling copies the bytes
    assert back.provenance.checks == {"note": "x"}


def test_the_json_keeps_its_content_under_the_parts_names():
    """Written again by this version, the old result's JSON holds the old file's content, value for
    value, each field under its part (:func:`migrate_v2`), and the same summary."""
    old = json.loads((OLD / "result.json").read_text())
    again = json.loads(json.dumps(load_result(OLD).to_json_dict(), allow_nan=True))
    migrated, _ = migrate_v2(old, {})
    assert {k: v for k, v in again.items() if k != "summary"} == migrated
    assert again["summary"] == old["summary"]
