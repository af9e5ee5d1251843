"""``lift_offset``: derivatives, no effect at nominal, acts in attached flow only; and in the
diagnosis, a pitch offset and a uniform lift shift are ``ambiguous`` on data that
stay in attached flow and told apart on data that reach stall."""

import numpy as np

from test_diagnosis import hidden, run
from test_effects_chain import check_effect_derivatives, check_nominal_is_no_effect, relative_change, tsr_sweep

from calib.rotor.library import load_rotor
from calib.types import OperatingConditions


def test_lift_offset_jacobian_matches_central_differences():
    check_effect_derivatives("lift_offset", {}, [0.05])


def test_lift_offset_at_nominal_is_no_effect():
    check_nominal_is_no_effect("lift_offset", {})


def test_lift_offset_acts_in_attached_flow_not_in_stall():
    # NREL 5-MW at rated speed: λ 6 (attached, below the optimum: more lift, more power) vs λ 2.5
    # (outboard stalled)
    d = relative_change("lift_offset", [0.1], tsr_sweep([6.0, 2.5]), channels=("power", "fn@0.9"))
    assert d[0, 0] > 0.02 and d[0, 1] > 0.02          # more lift, more power and normal force
    assert abs(d[1, 1]) < 0.2 * d[0, 1]                  # the stalled tip barely changes


PITCH_TRUTH = {"pitch_offset": {"pitch_offset": 1.0}}
CANDIDATES = ("pitch_offset", "lift_offset", "wind_speed_scale")


def test_pitch_offset_and_lift_shift_are_ambiguous_in_attached_flow():
    """Region-2 operation at one tip-speed ratio and fine pitch: every section stays below
    stall, where a 1 deg pitch offset is a uniform lift shift, so the data cannot tell them
    apart and the workflow says so instead of guessing."""
    rotor = load_rotor("nrel5mw")
    v = np.linspace(5.0, 10.0, 11)
    cond = OperatingConditions(v, 7.5 * v / rotor.rotor_radius * 30 / np.pi, np.zeros(v.size))
    d = run(hidden(PITCH_TRUTH, cond, 9020, channels=("power", "thrust")), candidates=CANDIDATES,
            recalibrate=False)
    assert d.effect == "ambiguous", d.rounds[0]["reason"]
    assert set(d.rounds[0]["ambiguous"]) == {"pitch_offset", "lift_offset"}


def test_pitch_offset_named_when_the_data_reach_stall():
    """A λ × pitch campaign into stall: the pitch offset moves the stall onset, a lift shift
    does not; the pitch offset is named."""
    rotor = load_rotor("nrel5mw")
    cond = OperatingConditions(*_wide(rotor))
    d = run(hidden(PITCH_TRUTH, cond, 9021, channels=("power", "thrust")), candidates=CANDIDATES,
            recalibrate=False)
    assert d.effect == "pitch_offset", d.rounds[0]["reason"]


def _wide(rotor, rpm=10.0):
    lam, pitch = np.meshgrid(np.linspace(3.0, 11.0, 9), (-1.0, 3.0, 7.0, 11.0), indexing="ij")
    v = rpm * np.pi / 30 * rotor.rotor_radius / lam.ravel()
    return v, np.full(v.size, rpm), pitch.ravel()
