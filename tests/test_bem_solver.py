"""Properties of the native BEM solver: converged roots, statuses, invariances."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from calib.bem import BemSettings, solve_bem
from calib.bem.kinematics import curvature, wind_components
from calib.bem.multiple_roots import SCAN_STEP_DEG, lowest_roots
from calib.bem.polar_grid import SectionPolars
from calib.bem.residual import SectionGeometry, section_equations
from calib.bem.point_status import INDUCTION_LIMIT
from calib.models.bem_model import BemModel
from calib.rotor.library import load_phase_vi_measurements, load_rotor, reference_path
from calib.types import OperatingConditions, Status
from synthetic import synthetic_rotor


def recomputed_residual(rotor, res, settings, cond, k):
    """Residual of the section equations at the returned φ for point ``k``, with the local
    velocities rebuilt from the kinematics (not from the solver's own inductions, which would
    make the check circular)."""
    polars = SectionPolars.from_rotor(rotor)
    interior = (rotor.r > rotor.hub_radius * (1 + 1e-9)) & (rotor.r < rotor.tip_radius * (1 - 1e-9))
    x_az, y_az, z_az, cone, _ = curvature(rotor.r, rotor.precurve, rotor.presweep, np.radians(rotor.precone_deg))
    azimuth = np.linspace(0.0, 2 * np.pi, res.n_sectors + 1)[:-1]
    vx, vy, _, _ = wind_components(x_az, y_az, z_az, cone, azimuth, cond.wind_speed[[k]],
                                   cond.rotor_speed[[k]] * np.pi / 30, np.radians(cond.yaw[[k]]),
                                   np.radians(rotor.tilt_deg), rotor.hub_height, settings.shear_exponent)
    phi = res.sections["phi"][k][:, interior].ravel()
    alpha = res.sections["alpha_deg"][k][:, interior].ravel()
    station = np.broadcast_to(np.flatnonzero(interior), (res.n_sectors, interior.sum())).ravel()
    cl, cd, _, _ = polars.lookup(alpha, station)
    r, c = rotor.r[station], rotor.chord[station]
    geo = SectionGeometry(r, c, rotor.n_blades * c / (2 * np.pi * r), rotor.hub_radius, rotor.tip_radius,
                          rotor.n_blades)
    eq = section_equations(phi, cl, cd, vx[0][:, interior].ravel(), vy[0][:, interior].ravel(), geo,
                           tip_loss=settings.tip_loss, hub_loss=settings.hub_loss)
    return eq["residual"], phi


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n_st=st.integers(5, 25), radius=st.floats(5.0, 100.0), hub=st.floats(0.03, 0.25),
       blades=st.integers(2, 4), tsr=st.floats(2.0, 12.0), chord_scale=st.floats(0.5, 2.0),
       twist=st.floats(-5.0, 10.0), wind=st.floats(3.0, 30.0), pitch=st.floats(-5.0, 30.0),
       yaw=st.floats(-30.0, 30.0), tilt=st.floats(0.0, 8.0), precone=st.floats(-4.0, 4.0),
       shear=st.floats(0.0, 0.3), curve=st.floats(-0.05, 0.05))
def test_random_rotors_converge_to_a_root(n_st, radius, hub, blades, tsr, chord_scale, twist, wind, pitch,
                                          yaw, tilt, precone, shear, curve):
    rotor = synthetic_rotor(n_st, radius, hub, blades, 7.0, precone, tilt, 2.0 * radius, chord_scale, twist,
                            curve * radius)
    rpm = tsr * wind / radius * 30 / np.pi
    cond = OperatingConditions([wind], [rpm], [pitch], 1.225, [yaw])
    s = BemSettings(shear_exponent=shear)
    res = solve_bem(rotor, cond, s)
    # positive drag everywhere: Ning's brackets guarantee a root, so every point must converge
    assert res.status[0] == Status.CONVERGED, res.messages[0]
    for name in ("power", "thrust", "torque", "root_flap_moment", "root_edge_moment"):
        assert np.isfinite(getattr(res, name)[0])
    R, phi = recomputed_residual(rotor, res, s, cond, 0)
    assert np.all(np.abs(R) < 1e-7)
    assert np.all((phi > -np.pi / 4 - 1e-12) & (phi < np.pi))


@settings(max_examples=30, deadline=None)
@given(field=st.sampled_from(["wind_speed", "rotor_speed", "air_density", "pitch", "yaw"]),
       bad=st.sampled_from([np.nan, np.inf, -np.inf, -1.0, 0.0, 1e3]))
def test_invalid_conditions_give_failed_status_not_nan(field, bad):
    rotor = synthetic_rotor()
    good = dict(wind_speed=[8.0, 8.0], rotor_speed=[15.0, 15.0], pitch=[0.0, 0.0], air_density=[1.225, 1.225],
                yaw=[0.0, 0.0])
    good[field] = [good[field][0], bad]
    res = solve_bem(rotor, OperatingConditions(**good))
    valid = {"wind_speed": bad > 0 and np.isfinite(bad), "rotor_speed": bad > 0 and np.isfinite(bad),
             "air_density": bad > 0 and np.isfinite(bad), "pitch": abs(bad) <= 180,
             "yaw": abs(bad) < 90}[field]
    assert res.status[0] == Status.CONVERGED
    if valid and field == "rotor_speed" and bad == 1e3:
        # λ ≈ 520: a valid input, but the induction leaves the physical range (|a| > 2)
        assert res.status[1] == Status.NOT_CONVERGED
        assert "axial induction" in res.messages[1]
        assert np.isnan(res.power[1])
    elif valid:
        assert res.status[1] == Status.CONVERGED, res.messages[1]
        assert np.isfinite(res.power[1])
    else:
        assert res.status[1] == Status.INVALID_INPUT
        assert field in res.messages[1]
        assert np.isnan(res.power[1])          # flagged by the status, never a silent number
    assert np.isfinite(res.power[0])


def test_negative_drag_is_reported_and_the_correction_field_cannot_cause_it():
    """A polar stage that takes C_D to zero or below is refused at that point (the BEM needs
    positive drag); the correction field itself holds the drag at its floor, so the same
    downward field evaluates."""
    from calib.corrections import CorrectionGrid
    from calib.effects import CorrectionFieldEffect
    from calib.effects.base import Effect

    class DragSink(Effect):
        name = "drag_sink"
        stage = "polar"
        PARAMETERS = ()

        def apply(self, theta, state, ctx):
            return state.replace(cd=state.cd - 0.5)

    rotor = synthetic_rotor()
    cond = OperatingConditions([8.0], [15.0], [0.0])
    res = solve_bem(rotor, cond, effects=[DragSink()], p=np.zeros(0))
    assert res.status[0] == Status.INVALID_INPUT
    assert "C_D <= 0" in res.messages[0]
    grid = CorrectionGrid([-10.0, 0.0, 10.0, 20.0], [0.0, 0.5, 1.0])
    p = np.zeros(grid.n_params)
    p[grid.n_lift:] = -0.5            # would drive C_D negative everywhere without the floor
    res = solve_bem(rotor, cond, effects=[CorrectionFieldEffect(grid)], p=p)
    assert res.status[0] == Status.CONVERGED, res.messages[0]


def test_vectorized_equals_one_at_a_time():
    rotor = synthetic_rotor(precone_deg=2.5, tilt_deg=5.0)
    rng = np.random.default_rng(3)
    v = rng.uniform(4, 20, 12)
    cond = OperatingConditions(v, rng.uniform(8, 20, 12), rng.uniform(0, 15, 12), 1.2, rng.uniform(-20, 20, 12))
    s = BemSettings(shear_exponent=0.14)
    batch = solve_bem(rotor, cond, s)
    for k in range(len(cond)):
        one = solve_bem(rotor, cond.subset([k]), s)
        assert one.power[0] == pytest.approx(batch.power[k], rel=1e-12)
        assert one.root_flap_moment[0] == pytest.approx(batch.root_flap_moment[k], rel=1e-12)


def test_axisymmetric_case_independent_of_sector_count():
    rotor = synthetic_rotor(precone_deg=3.0)
    cond = OperatingConditions([7.0, 11.0], [14.0, 16.0], [0.0, 4.0])
    one = solve_bem(rotor, cond, BemSettings(n_sectors=1))
    eight = solve_bem(rotor, cond, BemSettings(n_sectors=8))
    np.testing.assert_allclose(one.thrust, eight.thrust, rtol=1e-10)
    np.testing.assert_allclose(one.power, eight.power, rtol=1e-10)


def test_momentum_limits_without_losses():
    """Without losses and wake rotation the local thrust equals momentum: dT = 4πρ r V² a(1-a) dr.

    Exact (drag included) because the same c_n drives the axial induction and the normal load."""
    rotor = synthetic_rotor(n_stations=30)
    s = BemSettings(tip_loss=False, hub_loss=False, wake_rotation=False)
    res = solve_bem(rotor, OperatingConditions([8.0], [14.0], [2.0]), s)
    a = res.sections["a"][0, 0]
    r = rotor.r
    inner = (r > rotor.hub_radius * 1.01) & (r < rotor.tip_radius * 0.99) & (a < 0.4)
    npb = rotor.n_blades * res.sections["Np"][0, 0]          # N' B = ½ρW²c c_n B
    momentum = 4 * np.pi * 1.225 * r * 8.0 ** 2 * a * (1 - a)
    np.testing.assert_allclose(npb[inner], momentum[inner], rtol=1e-6)


@pytest.mark.parametrize("axial,tangential", [(True, True), (False, True), (True, False), (False, False)])
def test_drag_switches_act_on_the_induction_only(axial, tangential):
    """AeroDyn's AIDrag / TIDrag: each switch removes C_D from its own induction equation only;
    the loads are rebuilt by hand from φ, a, a' and the polar and always contain the drag."""
    rotor = synthetic_rotor(n_stations=25)
    wind, rpm, rho = 8.0, 14.0, 1.225
    s = BemSettings(tip_loss=False, hub_loss=False, drag_in_axial_induction=axial,
                    drag_in_tangential_induction=tangential, use_tilt=False)
    res = solve_bem(rotor, OperatingConditions([wind], [rpm], [1.0], rho), s)
    assert res.status[0] == Status.CONVERGED, res.messages[0]
    sec = {k: v[0, 0] for k, v in res.sections.items()}
    r = rotor.r
    inner = (r > rotor.hub_radius * 1.01) & (r < rotor.tip_radius * 0.99)
    phi, a, ap, cl, cd = (sec[k][inner] for k in ("phi", "a", "ap", "cl", "cd"))
    r, chord = r[inner], rotor.chord[inner]
    sp, cp = np.sin(phi), np.cos(phi)
    # loads from the kinematics (no precone, tilt or yaw: V_x = V, V_y = Ωr) and the full c_n, c_t
    w2 = (wind * (1 - a)) ** 2 + (rpm * np.pi / 30 * r * (1 + ap)) ** 2
    q = 0.5 * rho * w2 * chord
    np.testing.assert_allclose(sec["Np"][inner], q * (cl * cp + cd * sp), rtol=1e-10)
    np.testing.assert_allclose(sec["Tp"][inner], q * (cl * sp - cd * cp), rtol=1e-10)
    # the drag terms are not negligible here, so the load check above can tell them apart
    assert np.max(np.abs(cd * cp / (cl * sp - cd * cp))) > 0.05
    # induction from drag-free or full coefficients, each switch on its own equation (F = 1)
    sigma = rotor.n_blades * chord / (2 * np.pi * r)
    kappa = {d: sigma * (cl * cp + d * cd * sp) / (4 * sp ** 2) for d in (0, 1)}
    kappa_p = {d: sigma * (cl * sp - d * cd * cp) / (4 * sp * cp) for d in (0, 1)}
    mom = kappa[int(axial)] <= 2 / 3                       # momentum branch (not Buhl's)
    assert mom.sum() >= 10
    np.testing.assert_allclose(a[mom], (kappa[int(axial)] / (1 + kappa[int(axial)]))[mom], rtol=1e-10)
    np.testing.assert_allclose(ap, kappa_p[int(tangential)] / (1 - kappa_p[int(tangential)]), rtol=1e-10)
    # ... and not the other variant (the switches change the solution measurably)
    other_a = kappa[1 - int(axial)] / (1 + kappa[1 - int(axial)])
    other_ap = kappa_p[1 - int(tangential)] / (1 - kappa_p[1 - int(tangential)])
    assert np.max(np.abs(other_a[mom] / a[mom] - 1)) > 1e-3
    assert np.max(np.abs(other_ap / ap - 1)) > 1e-3


def test_power_equals_torque_times_speed_and_coefficients():
    rotor = synthetic_rotor()
    cond = OperatingConditions([6.0, 9.0], [12.0, 16.0], [0.0, 1.0], [1.2, 1.225])
    res = solve_bem(rotor, cond)
    omega = cond.rotor_speed * np.pi / 30
    np.testing.assert_allclose(res.power, res.torque * omega, rtol=1e-12)
    area = np.pi * rotor.tip_radius ** 2
    np.testing.assert_allclose(res.cp, res.power / (0.5 * cond.air_density * area * cond.wind_speed ** 3),
                               rtol=1e-12)


def brute_force_roots(rotor, cond, k, station, polars=None, n_grid=40001):
    """φ of every sign change of the residual on a uniform grid of Ning's first bracket (ε, π/2) at
    one station of an axisymmetric point (one sector), independent of the solver's search.

    Returns the sign-changing grid intervals, shape (n_roots, 2) [rad]."""
    polars = polars or SectionPolars.from_rotor(rotor)
    x_az, y_az, z_az, cone, _ = curvature(rotor.r, rotor.precurve, rotor.presweep, np.radians(rotor.precone_deg))
    vx, vy, _, _ = wind_components(x_az, y_az, z_az, cone, np.zeros(1), cond.wind_speed[[k]],
                                   cond.rotor_speed[[k]] * np.pi / 30, np.radians(cond.yaw[[k]]), 0.0,
                                   rotor.hub_height, 0.0)
    phi = np.linspace(1e-6, np.pi / 2, n_grid)
    n = phi.size
    theta = np.radians(rotor.twist_deg[station] + cond.pitch[k])
    cl, cd, _, _ = polars.lookup(np.degrees(phi - theta), np.full(n, station))
    r, c = rotor.r[station], rotor.chord[station]
    geo = SectionGeometry(np.full(n, r), np.full(n, c), np.full(n, rotor.n_blades * c / (2 * np.pi * r)),
                          rotor.hub_radius, rotor.tip_radius, rotor.n_blades)
    R = section_equations(phi, cl, cd, np.full(n, vx[0, 0, station]), np.full(n, vy[0, 0, station]),
                          geo)["residual"]
    j = np.flatnonzero((R[1:] > 0) != (R[:-1] > 0))
    return np.column_stack([phi[j], phi[j + 1]])


def test_phase_vi_20ms_several_roots_flagged_and_smallest_phi_kept():
    """Phase VI sequence H at 20 m/s: three roots at r/R = 0.994 (α ≈ 17.5, 19.5, 20.0 deg). The point
    stays converged, is flagged (result, message, model extras) and keeps the smallest-φ root of an
    independent brute-force scan; no other point is flagged."""
    rotor = load_rotor("phase_vi")
    meas = load_phase_vi_measurements()["performance"]
    cond = OperatingConditions(meas["wind_speed"], meas["rotor_speed"], 3.0, meas["air_density"], 0.0)
    settings = BemSettings(use_tilt=False)
    res = solve_bem(rotor, cond, settings)
    assert res.n_failed == 0
    k = int(np.flatnonzero(cond.wind_speed == 20.0)[0])
    np.testing.assert_array_equal(res.multiple_roots, np.arange(len(cond)) == k)
    assert res.n_multiple_root_sections[k] == 1
    assert "several roots" in res.messages[k] and "0.994" in res.messages[k]
    assert all(m == "" for j, m in enumerate(res.messages) if j != k)
    station = int(np.argmin(np.abs(rotor.eta - 0.994)))
    assert res.sections["n_roots"][k, 0, station] == 3
    roots = brute_force_roots(rotor, cond, k, station)
    assert len(roots) == 3
    kept = res.sections["phi"][k, 0, station]
    assert roots[0, 0] <= kept <= roots[0, 1]
    assert res.sections["alpha_deg"][k, 0, station] == pytest.approx(17.5, abs=0.1)
    ev = BemModel(rotor, None, ("torque",), settings, nuisance=()).evaluate(np.zeros(0), cond)
    np.testing.assert_array_equal(ev.extras["multiple_roots"], res.multiple_roots)
    np.testing.assert_array_equal(ev.extras["n_multiple_root_sections"], res.n_multiple_root_sections)


def test_root_pair_closer_than_the_sample_step_is_found():
    """IEA 3.4-MW, row 41 of CCBlade's table (18.6 m/s, pitch 19.8 deg), one sector, CCAirfoil's polar
    smoothing: at r/R = 0.198 two of three roots lie 0.16 deg apart, closer than the sampling step of
    the search, and no sample falls between them; the sampled extremum is refined, the point flagged
    and the smallest-φ root kept."""
    rotor = load_rotor("iea3.4")
    table = np.loadtxt(reference_path("IEA-3.4-130-RWT_performance_ccblade.dat"))
    cond = OperatingConditions(table[[41], 0], table[[41], 1], table[[41], 2])
    polars = SectionPolars.from_rotor(rotor, smoothing=(0.01, 0.001))
    res = solve_bem(rotor, cond, BemSettings(use_tilt=False, n_sectors=1), polars=polars)
    station = int(np.argmin(np.abs(rotor.eta - 0.198)))
    roots = brute_force_roots(rotor, cond, 0, station, polars)
    assert len(roots) == 3
    assert np.diff(roots.mean(axis=1)).min() < np.radians(SCAN_STEP_DEG)
    assert res.status[0] == Status.CONVERGED
    assert res.multiple_roots[0] and res.sections["n_roots"][0, 0, station] >= 3
    assert roots[0, 0] <= res.sections["phi"][0, 0, station] <= roots[0, 1]


def test_lowest_roots_on_an_analytic_residual():
    """R(φ) = (φ − r1)(φ − r2)(φ − r3) (negative below r1, like Ning's residual), started at the top root:
    a pair 0.001 rad apart, a descent through two windows, a single root, and a pair out of reach."""
    r = np.array([[0.300, 0.301, 0.350],      # pair closer than the step, next to the root
                  [0.300, 0.360, 0.420],      # each root one window below the previous one
                  [0.300, 5.000, 6.000],      # one root in the bracket
                  [0.100, 0.120, 0.400]])     # the pair lies beyond the window: not seen
    start = np.array([0.350, 0.420, 0.300, 0.400])

    def residual(idx, phi):
        return (phi - r[idx, 0]) * (phi - r[idx, 1]) * (phi - r[idx, 2])

    phi, f, n_roots = lowest_roots(residual, start, residual(np.arange(4), start), np.full(4, 1e-6),
                                   np.full(4, np.pi / 2), np.ones(4, bool), np.radians(SCAN_STEP_DEG),
                                   np.radians(5.0), 1e-12)
    np.testing.assert_allclose(phi, [0.300, 0.300, 0.300, 0.400], atol=1e-10)
    np.testing.assert_array_equal(n_roots, [3, 3, 1, 1])
    assert np.all(np.abs(f) <= 1e-12)


def test_induction_far_outside_the_physical_range_is_flagged():
    """IEA 15-MW at its minimum rotor speed in 0.1 m/s of wind (λ ≈ 630): sections with a ≈ 19 must not
    be reported converged; the same rotor at 3 m/s is."""
    rotor = load_rotor("iea15")
    sch = rotor.schedule
    cond = OperatingConditions([0.1, 3.0], [sch.min_rotor_speed] * 2, [sch.fine_pitch] * 2)
    res = solve_bem(rotor, cond)
    a = res.sections["a"][0]
    assert np.nanmax(np.abs(a)) > 5 * INDUCTION_LIMIT            # the solver did find roots there (a ≈ 19)
    assert res.status[0] == Status.NOT_CONVERGED
    assert "axial induction" in res.messages[0] and f"|a| <= {INDUCTION_LIMIT:g}" in res.messages[0]
    assert np.isnan(res.power[0]) and np.isnan(res.thrust[0])
    assert res.status[1] == Status.CONVERGED, res.messages[1]
    assert np.nanmax(np.abs(res.sections["a"][1])) <= INDUCTION_LIMIT
