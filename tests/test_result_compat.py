"""Results written by earlier versions load into the nested result and predict (tests/data/results)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib.calibration.result import load_result
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
    assert res.p_hat is res.estimate.p_hat              # the flat names read the parts
    assert res.identifiability.retained.dtype == bool and res.fit.multiple_roots.dtype == bool
    assert res.provenance.model_spec and res.name == "field loads"
    assert res.uncertainty.gain.size and res.estimator == "map"
    assert "p_hat" not in res.to_json_dict() and "theta_nominal_linearization" not in res.flat_fields()


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
    text = (tmp_path / "result.json").read_text().replace('"schema_version": 2', '"schema_version": 1')
    (tmp_path / "result.json").write_text(text)
    with pytest.raises(InputError, match="unsupported result schema 1, expected 2"):
        load_result(tmp_path)


def test_the_flat_names_write_through_to_the_parts_and_replace_copies():
    res = load_result(OLD)
    res.checks = {"note": "x"}
    assert res.provenance.checks == {"note": "x"}
    other = res.replace(p_hat=res.p_hat + 1.0, name="moved")
    assert other.name == "moved" and np.allclose(other.estimate.p_hat, res.estimate.p_hat + 1.0)
    assert other.estimate is not res.estimate and res.name == "field loads"
    other.p_hat = np.zeros_like(res.p_hat)                    # the copy's part, not the original's
    assert np.any(res.p_hat != 0)
    fit = res.fit
    assert res.replace(fit=fit, chi2_after=1.0).fit.chi2_after == 1.0 and fit.chi2_after != 1.0
    with pytest.raises(AttributeError, match="no attribute 'p_hut'"):
        res.p_hut
    import pickle

    back = pickle.loads(pickle.dumps(res))      # (executors pickle what they return)
    np.testing.assert_array_equal(back.p_hat, res.p_hat)      # exact: pickling copies the bytes
    assert back.checks == {"note": "x"}


def test_the_json_keeps_its_content_under_the_same_names():
    """Written again by this version, the old result's JSON is the old file's, key for key."""
    import json

    res = load_result(OLD)
    again = json.loads(json.dumps(res.to_json_dict(), allow_nan=True))
    assert again == json.loads((OLD / "result.json").read_text())
