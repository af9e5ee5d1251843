"""``rotational_augmentation``: derivatives of every variant, fingerprint (power up at low λ only)."""

import numpy as np
import pytest

from calib.effects import make_effect
from calib.errors import InputError
from calib.models.bem_model import BemModel
from test_effects_chain import (FP_LAMBDA, FP_SETTINGS, check_effect_derivatives, check_nominal_is_no_effect,
                                nrel5mw, relative_change, tsr_sweep)

VARIANTS = {"snel": {}, "du_selig": {"variant": "du_selig"},
            "chaviaropoulos_hansen": {"variant": "chaviaropoulos_hansen", "inviscid_lift": "thin_airfoil"}}


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_rotational_augmentation_jacobian_matches_central_differences(variant):
    check_effect_derivatives("rotational_augmentation", VARIANTS[variant], [0.8])


@pytest.mark.parametrize("variant", list(VARIANTS))
def test_rotational_augmentation_at_zero_strength_is_the_2d_polar(variant):
    check_nominal_is_no_effect("rotational_augmentation", VARIANTS[variant])


@pytest.mark.parametrize("variant", ["snel", "du_selig", "chaviaropoulos_hansen"])
def test_rotational_augmentation_raises_power_at_low_lambda_only(variant):
    dp = relative_change("rotational_augmentation", [1.0], tsr_sweep(), variant=variant)[:, 0]
    low, high = dp[FP_LAMBDA <= 4.0], dp[FP_LAMBDA >= 9.0]
    assert np.all(low > 0.05), low                       # stalled inboard sections lift more
    assert np.abs(high).max() < 0.1 * low.min(), (low, high)
    # in the polar: more lift at high α on the inboard blade
    model = BemModel(nrel5mw(), None, ("power",), FP_SETTINGS, (),
                     effects=[make_effect("rotational_augmentation", variant=variant)])
    r0, r1 = model.solve([0.0], tsr_sweep()), model.solve([1.0], tsr_sweep())
    dcl = r1.sections["cl"] - r0.sections["cl"]
    eta = nrel5mw().eta
    inboard = ((eta > 0.2) & (eta < 0.45))[None, None, :]
    assert np.nanmean(dcl[(r0.sections["alpha_deg"] > 15.0) & inboard]) > 0.1


def test_rotational_augmentation_options_are_checked():
    with pytest.raises(InputError, match="valid: variant, inviscid_lift, alpha_full_deg, alpha_end_deg, nominal"):
        make_effect("rotational_augmentation", varient="snel")
    with pytest.raises(InputError, match="valid: snel, du_selig, chaviaropoulos_hansen"):
        make_effect("rotational_augmentation", variant="lindenburg")
