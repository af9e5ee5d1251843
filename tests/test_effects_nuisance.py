"""The nuisance effects ``pitch_offset`` and ``wind_speed_scale``: derivatives and fingerprints."""

import numpy as np

from calib.models.base import OperatingConditions
from calib.models.bem_model import BemModel
from floats import assert_same_numbers
from test_effects_chain import (FP_RPM, FP_SETTINGS, check_effect_derivatives, nrel5mw, tsr_sweep)


def test_pitch_offset_jacobian_matches_central_differences():
    check_effect_derivatives("pitch_offset", {}, [0.6])


def test_wind_speed_scale_jacobian_matches_central_differences():
    check_effect_derivatives("wind_speed_scale", {}, [1.04])


def test_pitch_offset_shifts_cp_along_pitch():
    lam = np.repeat([5.0, 7.5, 10.0], 3)
    beta = np.tile([0.0, 2.0, 4.0], 3)
    model = BemModel(nrel5mw(), None, ("power",), FP_SETTINGS, ("pitch_offset",))
    cp_offset = model.solve([1.5], tsr_sweep(lam, beta)).cp
    assert_same_numbers(cp_offset, model.solve([0.0], tsr_sweep(lam, beta + 1.5)).cp)
    assert np.all(np.abs(cp_offset / model.solve([0.0], tsr_sweep(lam, beta)).cp - 1) > 1e-3)


def test_wind_speed_scale_stretches_the_power_curve():
    cond = tsr_sweep()
    model = BemModel(nrel5mw(), None, ("power",), FP_SETTINGS, ("wind_scale",))
    scaled = model.solve([1.05], cond)
    moved = OperatingConditions(cond.wind_speed * 1.05, FP_RPM, 0.0)
    assert_same_numbers(scaled.power, model.solve([1.0], moved).power)
    np.testing.assert_allclose(scaled.cp, model.solve([1.0], moved).cp * 1.05 ** 3, rtol=1e-14)
