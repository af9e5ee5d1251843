"""``leading_edge_erosion``: derivatives, fingerprint (power down at every λ, drag not thrust, outboard only)."""

import numpy as np
import pytest

from calib.effects import make_effect
from test_effects_chain import (FP_LAMBDA, check_effect_derivatives, check_nominal_is_no_effect, relative_change,
                                tsr_sweep)


@pytest.mark.parametrize("variant", ["stall", "slope"])
def test_leading_edge_erosion_jacobian_matches_central_differences(variant):
    check_effect_derivatives("leading_edge_erosion", {"variant": variant}, [0.75, 0.01, 0.15])


def test_slope_variant_loses_lift_in_attached_flow_where_the_stall_variant_does_not():
    """Near the optimum (attached flow) the slope variant lowers the outboard normal force, the
    stall variant hardly: the out-of-family battery's erosion (a lift-slope loss from r/R 0.6)
    was named with tip_loss as a second effect 38 of 40 times with the stall form alone."""
    stall = relative_change("leading_edge_erosion", [0.7, 0.0, 0.1], tsr_sweep(), channels=("fn@0.95",))
    slope = relative_change("leading_edge_erosion", [0.7, 0.0, 0.1], tsr_sweep(), channels=("fn@0.95",),
                            variant="slope")
    attached = FP_LAMBDA >= 7.0
    assert np.all(slope[attached, 0] < -0.05) and np.all(np.abs(stall[attached, 0]) < 0.01)


def test_leading_edge_erosion_without_damage_is_no_effect():
    check_nominal_is_no_effect("leading_edge_erosion", {})


def test_leading_edge_erosion_lowers_power_everywhere_not_the_thrust_near_optimum():
    d = relative_change("leading_edge_erosion", [0.7, 0.01, 0.1], tsr_sweep(),
                        channels=("power", "thrust", "fn@0.5", "fn@0.95"))
    power, thrust, inboard, tip = d.T
    assert np.all(power < -0.02), power                   # C_P low at every λ
    attached = FP_LAMBDA >= 7.0                           # from the optimum up: attached flow, drag only
    assert np.abs(thrust[attached]).max() < 0.05 * np.abs(power[attached]).min()   # drag, not thrust
    assert np.all(np.diff(power[FP_LAMBDA >= 6.0]) < 0)  # the drag loss grows with λ past the optimum
    assert np.all(inboard == 0.0)                         # nothing inboard of the onset span
    assert np.all(tip[FP_LAMBDA <= 4.0] < -0.05)          # lift loss near stall at the eroded tip


def test_leading_edge_erosion_onset_moves_the_damage():
    cond = tsr_sweep(np.array([4.0, 8.0]))
    early = relative_change("leading_edge_erosion", [0.5, 0.01, 0.0], cond, channels=("power", "fn@0.6"))
    late = relative_change("leading_edge_erosion", [0.8, 0.01, 0.0], cond, channels=("power", "fn@0.6"))
    assert np.all(early[:, 0] < late[:, 0])               # more eroded span, more loss
    assert np.all(late[:, 1] == 0.0) and np.all(early[:, 1] != 0.0)


def test_erosion_cannot_make_a_section_cleaner():
    """Negative erosion (a lift gain, a drag reduction) is not erosion: the WISDEM correction3D truth
    of the out-of-family battery was named erosion with a negative lift loss 39 of 40 times while
    these bounds allowed it (tests/test_oof_battery.py now checks that data set is named right)."""
    from calib.errors import InputError

    for name in ("erosion_lift_loss", "erosion_drag_rise"):
        with pytest.raises(InputError, match="outside its bounds|bounds"):
            make_effect("leading_edge_erosion", nominal={name: -0.01})
