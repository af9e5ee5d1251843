"""Settling until a run's own check holds (``[steady] settle_rtol``, :func:`calib.fmu.settling.settled_window`).

The reference for the rule is the fixed window the adapter has always used: a run with ``settle_rtol`` must be,
sample for sample, the fixed run that settles the first number of revolutions whose window's halves agree to the
tolerance; and the physics reference is a long-settled run (the Øye lag of the bundled FMU with shaft tilt
decays over a few revolutions, so the fixed 2 + 2 window is off by up to about 0.16 % there).
"""

from __future__ import annotations

import numpy as np
import pytest

from calib.errors import InputError
from calib.fmu.build import mapping_path
from calib.fmu.rules import steady_rule
from calib.types import OperatingConditions

CHANNELS = ["power", "thrust", "root_flap_moment_blade1", "root_flap_moment_blade2"]
#: the lagged configuration of benchmarks/bench_fmu_run.py: Øye dynamic inflow, rigid blades, the FMU's shaft tilt
SWITCHES = dict(dynamic_inflow=True, flexible_blades=False, tower_shadow=False, shear=False, gravity=False,
                yaw=False, skewed_wake=False, stall_delay="snel")
WINDOW = dict(steps_per_revolution=16, settle_revolutions=2, average_revolutions=2)
PARAMETERS = ["pitch_offset_blade1", "stall_delay_strength"]
P = np.array([0.4, 1.5])
#: a slow point (low wind, tau_1 about 2.7 revolutions) and a fast one
CONDITIONS = OperatingConditions(np.array([5.0, 15.0]), np.array([7.0, 12.1]), np.array([0.0, 3.0]),
                                 np.array([1.225, 1.225]))


def _model(fmus, **steady):
    from calib.fmu.model import FmuModel
    return FmuModel(fmus["A"], mapping_path("A"), CHANNELS, parameters=PARAMETERS, corrections=False,
                    switches=SWITCHES, steady=dict(WINDOW, **steady), isolate=False)


def _outcomes(model) -> list:
    """The base-run outcome of each point of CONDITIONS at P (in this process)."""
    from calib.fmu.simulator import Simulator
    _, tasks, _ = model._tasks(P, CONDITIONS, False)
    sim = Simulator(model._plan)
    try:
        return [sim.cold_run(t, t.base, keep_state=False)[0] for t in tasks]
    finally:
        sim.close()


@pytest.mark.parametrize("value", [0.0, -1e-4, float("nan"), float("inf")])
def test_settle_rtol_must_be_positive(value):
    with pytest.raises(InputError, match=r"steady\.settle_rtol") as err:
        steady_rule(dict(WINDOW, settle_rtol=value), "mapping.toml")
    assert "mapping.toml" in str(err.value)


def test_left_out_is_the_fixed_window():
    rule = steady_rule(dict(WINDOW), "mapping.toml")
    assert rule.settle_rtol is None
    assert rule.replace(settle_rtol=1e-4).settle_rtol == 1e-4
    assert rule.replace(settle_rtol=1e-4).replace(settle_revolutions=3).settle_rtol == 1e-4


def test_a_tolerance_never_met_gives_the_fixed_window_bit_for_bit(fmus):
    fixed, never = _outcomes(_model(fmus)), _outcomes(_model(fmus, settle_rtol=1e-300))
    for a, b in zip(fixed, never):
        assert a.ok and b.ok
        assert a.steps == b.steps == 4 * WINDOW["steps_per_revolution"]
        assert np.array_equal(a.mean, b.mean) and np.array_equal(a.halves, b.halves)
        assert np.array_equal(a.harmonics, b.harmonics, equal_nan=True)
        assert a.counters == b.counters


def test_stops_at_the_first_window_whose_halves_agree(fmus):
    """Against fixed windows of 0, 1, 2 ... settle revolutions: the adaptive run is the first one whose halves
    agree to the tolerance (relative to |mean|: these outputs vary by under 1 % over a revolution, so |mean| >
    the samples' std), the same samples; every earlier window fails the tolerance."""
    tol, most = 3e-4, 10
    n = WINDOW["steps_per_revolution"]
    adaptive = _outcomes(_model(fmus, settle_rtol=tol, settle_revolutions=most))
    fixed = [_outcomes(_model(fmus, settle_revolutions=s)) for s in range(most + 1)]
    checked = [0, 1, 2, 3]
    settled = []
    for k, a in enumerate(adaptive):
        agree = [bool(np.all(np.abs(f[k].halves[1, checked] - f[k].halves[0, checked])
                             <= tol * np.abs(f[k].mean[checked]))) for f in fixed]
        s = agree.index(True) if any(agree) else most
        settled.append(s)
        assert a.steps == (s + 2) * n
        assert np.array_equal(a.mean, fixed[s][k].mean)
        assert a.simulated == pytest.approx((s + 2) * 60.0 / (CONDITIONS.rotor_speed[k] * n) * n, rel=1e-12)
    # the slow point needs more settling than the fast one, and more than the fixed window gives it
    assert settled[0] > settled[1]
    assert settled[0] > WINDOW["settle_revolutions"]


def test_closer_to_the_settled_state_than_the_fixed_window(fmus):
    """The Øye lag: against 30 settle revolutions (settled to well under 1e-5 relative), the fixed 2 + 2 window of
    the slow point is off by about 1e-3 relative; settling until the halves agree to 1e-4 leaves a geometric tail of
    about tol x r / (1 - r) with r about 0.7 per revolution, i.e. a few 1e-4."""
    ref = _outcomes(_model(fmus, settle_revolutions=30))
    fixed = _outcomes(_model(fmus))
    adaptive = _outcomes(_model(fmus, settle_rtol=1e-4, settle_revolutions=20))
    err_fixed = np.abs(fixed[0].mean[:4] / ref[0].mean[:4] - 1).max()
    err_adaptive = np.abs(adaptive[0].mean[:4] / ref[0].mean[:4] - 1).max()
    assert err_fixed > 5e-4
    assert err_adaptive < 5e-4
    assert err_adaptive < err_fixed / 2


def test_warm_start_and_saved_states_after_an_adaptive_base_run(fmus):
    """With a warm-started Jacobian the base run also keeps its state (taken at the run's end, settled at least as
    far as its window): the base values are still the adaptive evaluation's, bit for bit; the perturbed runs
    restored from that state run and converge."""
    from calib.fmu.model import FmuModel
    model = FmuModel(fmus["A"], mapping_path("A"), CHANNELS, parameters=PARAMETERS, corrections=False,
                     switches=SWITCHES, steady=dict(WINDOW, settle_rtol=3e-4, settle_revolutions=10), isolate=False,
                     jacobian=dict(warm_start=True, differences="forward", relative_step=0.1))
    assert model.can_get_state
    evaluation = model.evaluate(P, CONDITIONS)
    model.base_runs.clear()
    ev, G = model.jacobian(P, CONDITIONS)
    assert np.all(ev.status == evaluation.status) and np.array_equal(ev.values, evaluation.values)
    assert np.all(np.isfinite(G))
    # more pitch on blade 1: less angle of attack, less lift, less flap moment on blade 1
    assert G[0, 2, 0] < 0
