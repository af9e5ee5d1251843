"""``wind_tunnel_blockage``: derivatives through the thrust fixed point, fingerprint (error grows with C_T)."""

import numpy as np

from calib.effects import make_effect
from calib.models.base import OperatingConditions
from calib.models.bem_model import BemModel
from test_effects_chain import (FP_RPM, FP_SETTINGS, check_effect_derivatives, check_nominal_is_no_effect, nrel5mw,
                                relative_change)


def test_wind_tunnel_blockage_jacobian_matches_central_differences():
    # the thrust feedback couples every parameter: field nodes of both blocks and the nuisance too
    check_effect_derivatives("wind_tunnel_blockage", {}, [0.15], all_parameters=True)


def test_wind_tunnel_blockage_at_zero_is_the_free_stream():
    check_nominal_is_no_effect("wind_tunnel_blockage", {})


def test_wind_tunnel_blockage_error_grows_with_thrust():
    # at the optimal λ, pitch lowers the thrust: the power error follows the thrust
    pitch = np.array([0.0, 2.0, 4.0, 6.0, 8.0, 10.0])
    rotor = nrel5mw()
    cond = OperatingConditions(np.full(pitch.size, FP_RPM * np.pi / 30 * rotor.rotor_radius / 7.5), FP_RPM, pitch)
    effect = make_effect("wind_tunnel_blockage")
    res = BemModel(rotor, None, ("power",), FP_SETTINGS, (), effects=[effect]).solve([0.1], cond)
    ct = res.ct
    dp = relative_change("wind_tunnel_blockage", [0.1], cond)[:, 0]
    order = np.argsort(ct)
    assert np.all(np.diff(dp[order]) > 0), (ct, dp)
    assert dp[order[0]] > 0
    # the inflow is Glauert's speed for the model's own thrust (the fixed point holds)
    ratio = res.inflow_wind_speed / cond.wind_speed
    np.testing.assert_allclose(ratio - 1.0, 0.25 * 0.1 * effect.glauert(ct), rtol=1e-9)
    assert ct.max() > 0.8 > ct.min()                      # both branches of the factor


def test_wind_tunnel_blockage_continues_glauert_above_the_thrust_limit():
    effect = make_effect("wind_tunnel_blockage")
    ct = np.array([0.5, 0.79, 0.8, 0.81, 1.2, 2.0])
    g = effect.glauert(ct)
    below = ct <= 0.8
    np.testing.assert_allclose(g[below], ct[below] / np.sqrt(1 - ct[below]))
    h = 1e-7
    left, right = effect.glauert(np.array([0.8 - h])), effect.glauert(np.array([0.8 + h]))
    slope = (1 - 0.4) / 0.2 ** 1.5
    assert abs((right - left)[0] / (2 * h) - slope) < 1e-4 * slope      # C¹ at the limit
    assert np.all(np.isfinite(g)) and np.all(np.diff(g) > 0)
