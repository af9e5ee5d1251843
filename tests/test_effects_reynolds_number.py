"""``reynolds_number``: derivatives, fingerprint (C_P(λ) no longer collapses across wind speeds)."""

import numpy as np
import pytest

from calib.effects import make_effect
from calib.errors import InputError
from calib.models.base import OperatingConditions
from calib.models.bem_model import BemModel
from synthetic import synthetic_rotor
from test_effects_chain import FP_SETTINGS, check_effect_derivatives, check_nominal_is_no_effect, nrel5mw


def test_reynolds_number_jacobian_matches_central_differences():
    check_effect_derivatives("reynolds_number", {}, [0.3, 0.2])


def test_reynolds_number_at_zero_is_the_tables():
    check_nominal_is_no_effect("reynolds_number", {})


def test_reynolds_number_breaks_the_collapse_of_cp_lambda():
    # the same λ and pitch at two wind speeds (rotor speed scaled): one C_P without the effect
    lam = np.array([5.0, 7.5, 10.0])
    v_low, v_high = 4.0, 9.0
    rotor = nrel5mw()
    cond = OperatingConditions(np.r_[np.full(3, v_low), np.full(3, v_high)],
                               np.r_[lam * v_low, lam * v_high] / rotor.rotor_radius * 30 / np.pi, 0.0)
    model = BemModel(rotor, None, ("power",), FP_SETTINGS, (), effects=[make_effect("reynolds_number")])
    cp0 = model.solve([0.0, 0.0], cond).cp
    np.testing.assert_allclose(cp0[:3], cp0[3:], rtol=1e-10)
    cp = model.solve([0.3, 0.2], cond).cp
    assert np.all(cp[:3] < cp[3:] - 0.002), cp           # lower Re at low wind speed: more drag


def test_reynolds_number_needs_a_reference():
    cond = OperatingConditions([8.0], [15.0], [0.0])
    model = BemModel(synthetic_rotor(), None, ("power",), FP_SETTINGS, (), effects=["reynolds_number"])
    with pytest.raises(InputError, match="reference_reynolds"):
        model.evaluate([0.1, 0.0], cond)
    given = BemModel(synthetic_rotor(), None, ("power",), FP_SETTINGS, (),
                     effects=[make_effect("reynolds_number", reference_reynolds=3e6)])
    assert given.evaluate([0.1, 0.0], cond).n_failed == 0
