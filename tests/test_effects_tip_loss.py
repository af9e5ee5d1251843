"""``tip_loss``: derivatives, fingerprint (tip-gauge loads move, root and mid-span hardly)."""

import numpy as np

from test_effects_chain import (FP_LAMBDA, check_effect_derivatives, check_nominal_is_no_effect, relative_change,
                                tsr_sweep)


def test_tip_loss_jacobian_matches_central_differences():
    check_effect_derivatives("tip_loss", {}, [0.7])


def test_tip_loss_at_zero_strength_is_prandtl():
    check_nominal_is_no_effect("tip_loss", {})


def test_tip_loss_moves_tip_gauge_loads_more_than_root_loads():
    d = relative_change("tip_loss", [1.0], tsr_sweep(), channels=("fn@0.95", "root_flap_moment", "fn@0.5"))
    tip, root, mid = np.abs(d.T)
    assert np.all(tip > 2.5 * root), (tip, root)          # the flap moment integrates the tip, with arm
    assert np.all(tip > 20.0 * mid), (tip, mid)
    assert np.all(np.diff(tip[FP_LAMBDA >= 4.0]) > 0)     # the error grows with λ
