"""The compiled root search (calib.bem.kernel) against the numpy path it replaces.

The kernel runs the same bracket, iteration and residual, in the same order of operations:
values equal to the last bits of sin, cos, exp and acos (libm against numpy's loops). Those last
bits differ between processors and libm versions, so iteration counts are compared with a
tolerance (a last-bit difference in a residual may move a convergence test by one step in a
rare section), and so are the counts of roots per section (a root at a bracket end or a
near-tangent pair may be seen by one path only); roots and values are compared as solutions.
"""

import numpy as np
import pytest

from calib.bem import BemSettings, kernel, solve_bem
from calib.rotor.library import load_phase_vi_measurements, load_rotor
from calib.types import OperatingConditions, Status
from synthetic import synthetic_rotor

pytestmark = pytest.mark.skipif(kernel.library() is None, reason="compiled BEM kernel not available")


@pytest.fixture
def numpy_path(monkeypatch):
    """Run the block on the numpy path (the kernel switched off, then restored)."""
    def switch():
        monkeypatch.setattr(kernel, "_state", {"lib": None, "status": "numpy path (test)"})
    return switch


def _grid(rotor, tsr=np.linspace(1.0, 60.0, 13), pitch=np.linspace(-10.0, 90.0, 11), rpm=10.0):
    lam, beta = np.meshgrid(tsr, pitch, indexing="ij")
    wind = rpm * np.pi / 30 * rotor.rotor_radius / lam.ravel()
    return OperatingConditions(wind, np.full(wind.size, rpm), beta.ravel())


#: Sections whose count of roots may differ between the two paths, at most (a fraction, and at least one).
COUNT_MARGIN = 1e-3


def _assert_same_counts(fast, slow):
    """Iterations per section equal but for at most one step in at most 0.1 % of the sections (last
    bits of libm). Roots found per section: the count is a property of the residual only where its
    roots stand clear of the search's bracket ends and of each other; a root within round-off of a
    bracket end, or a pair near a tangency, may be seen by one path and not the other. So the counts
    agree but in at most 0.1 % of the sections (and one), by at most two roots (a near-tangent pair),
    at sections both paths searched (n_roots > 1 on one side); the kept root, which the values
    follow, is compared as a solution (:func:`_assert_same`) at every section."""
    it_fast, it_slow = fast.sections["iterations"], slow.sections["iterations"]
    off = it_fast != it_slow
    assert np.all(np.abs(it_fast - it_slow) <= 1), "iteration counts differ by more than one step"
    assert off.sum() <= max(1, 1e-3 * off.size), f"{off.sum()} of {off.size} sections differ in iterations"
    n_fast, n_slow = fast.sections["n_roots"], slow.sections["n_roots"]
    np.testing.assert_array_equal(np.isnan(n_fast), np.isnan(n_slow), err_msg="sections with a root")
    n_fast, n_slow = np.nan_to_num(n_fast), np.nan_to_num(n_slow)
    differ = n_fast != n_slow
    assert differ.sum() <= max(1, COUNT_MARGIN * differ.size), \
        f"{differ.sum()} of {differ.size} sections differ in their count of roots"
    assert np.all(np.abs(n_fast - n_slow) <= 2), "a count of roots differs by more than a near-tangent pair"
    assert np.all(np.maximum(n_fast, n_slow)[differ] > 1), "a count differs at a section with one root on both paths"
    # the points flagged for several roots differ only where a section's count does
    flagged = (n_fast > 1).any(axis=tuple(range(1, n_fast.ndim))) != (n_slow > 1).any(axis=tuple(range(1, n_slow.ndim)))
    assert not np.any(flagged & ~differ.any(axis=tuple(range(1, differ.ndim))))


def _assert_same(fast, slow):
    np.testing.assert_array_equal(fast.status, slow.status)
    _assert_same_counts(fast, slow)
    for name in ("phi", "a", "ap", "cl", "cd", "W"):
        np.testing.assert_allclose(fast.sections[name], slow.sections[name], rtol=1e-11, atol=1e-13, err_msg=name)
    for name in ("Np", "Tp"):
        scale = np.nanmax(np.abs(slow.sections[name]))
        np.testing.assert_allclose(fast.sections[name], slow.sections[name], rtol=1e-11, atol=1e-12 * scale,
                                   err_msg=name)
    for name in ("power", "thrust", "torque", "root_flap_moment", "root_edge_moment", "cp", "ct"):
        scale = np.nanmax(np.abs(getattr(slow, name)))
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=1e-11, atol=1e-12 * scale,
                                   err_msg=name)


SETTINGS = [BemSettings(use_tilt=False, n_sectors=1), BemSettings(shear_exponent=0.2),
            BemSettings(tip_loss=False, wake_rotation=False), BemSettings(hub_loss=False),
            BemSettings(drag_in_axial_induction=False, drag_in_tangential_induction=False)]


@pytest.mark.parametrize("settings", SETTINGS, ids=["axisymmetric", "shear", "no-tip-loss-no-wake-rotation",
                                                    "no-hub-loss", "no-drag-in-induction"])
def test_same_roots_and_values_as_the_numpy_path(settings, numpy_path):
    """Windmill and high-induction sections, and points whose sections find no bracket (λ up to 60,
    pitch up to 90 deg: every stage of Ning's bracket search)."""
    rotor = load_rotor("nrel5mw")
    cond = _grid(rotor)
    fast = solve_bem(rotor, cond, settings)
    numpy_path()
    slow = solve_bem(rotor, cond, settings)
    assert (slow.status == Status.CONVERGED).any() and (slow.status != Status.CONVERGED).any()
    _assert_same(fast, slow)


def test_same_roots_where_several_roots_are_searched(numpy_path):
    """Phase VI sequence H (three roots at r/R = 0.994 at 20 m/s), with sensitivities."""
    rotor = load_rotor("phase_vi")
    meas = load_phase_vi_measurements()["performance"]
    cond = OperatingConditions(meas["wind_speed"], meas["rotor_speed"], 3.0, meas["air_density"], 0.0)
    settings = BemSettings(use_tilt=False)
    fast = solve_bem(rotor, cond, settings, sensitivities=True)
    numpy_path()
    slow = solve_bem(rotor, cond, settings, sensitivities=True)
    assert slow.multiple_roots.any()
    _assert_same(fast, slow)
    for name, d in slow.sensitivities.columns.items():
        scale = np.max(np.abs(d), axis=(0, 1, 2))
        np.testing.assert_allclose(fast.sensitivities.columns[name], d, rtol=1e-9, atol=1e-10 * scale.max(),
                                   err_msg=name)


def test_random_rotor_same_as_numpy_path(numpy_path):
    rotor = synthetic_rotor(12, 20.0, 0.1, 2, 7.0, 2.0, 5.0, 40.0, 1.3, 3.0, 0.5)
    cond = _grid(rotor, tsr=np.linspace(2.0, 12.0, 6), pitch=np.linspace(-5.0, 30.0, 6), rpm=40.0)
    s = BemSettings(shear_exponent=0.1)
    fast = solve_bem(rotor, cond, s)
    numpy_path()
    _assert_same(fast, solve_bem(rotor, cond, s))


def test_switched_off_by_the_environment(monkeypatch):
    monkeypatch.setattr(kernel, "_state", {})
    monkeypatch.setenv(kernel.ENV, "numpy")
    assert kernel.library() is None
    assert kernel.status().startswith("numpy path")


def test_no_compiler_falls_back_or_fails_clearly(monkeypatch, tmp_path):
    monkeypatch.setattr(kernel, "_compiler", lambda: None)
    monkeypatch.setenv("CALIB_CACHE", str(tmp_path))            # nothing built there yet
    monkeypatch.setattr(kernel, "_state", {})
    monkeypatch.setattr(kernel.tempfile, "gettempdir", lambda: str(tmp_path / "tmp"))
    monkeypatch.delenv(kernel.ENV, raising=False)
    assert kernel.library() is None and "no C compiler" in kernel.status()
    monkeypatch.setattr(kernel, "_state", {})
    monkeypatch.setenv(kernel.ENV, "c")
    with pytest.raises(kernel.KernelBuildError, match="no C compiler"):
        kernel.library()


@pytest.mark.parametrize("rotor_name", ["phase_vi", "iea3.4"])
def test_screen_for_several_roots_selects_the_same_sections(rotor_name, numpy_path, monkeypatch):
    """The compiled screen (negative lift slope in the window, then the slope budget) picks exactly the
    sections the numpy screen picks."""
    from calib.bem import sections
    seen = []
    search = sections.lowest_roots

    def spy(residual, phi, fphi, lo, hi, candidates, *args, **kwargs):
        seen.append(candidates.copy())
        return search(residual, phi, fphi, lo, hi, candidates, *args, **kwargs)

    monkeypatch.setattr(sections, "lowest_roots", spy)
    rotor = load_rotor(rotor_name)
    cond = _grid(rotor, tsr=np.linspace(2.0, 12.0, 9), pitch=np.linspace(-5.0, 30.0, 8),
                 rpm=72.0 if rotor_name == "phase_vi" else 7.0)
    fast = solve_bem(rotor, cond, BemSettings(polar_smoothing=(0.1, 0.001)))
    numpy_path()
    slow = solve_bem(rotor, cond, BemSettings(polar_smoothing=(0.1, 0.001)))
    assert len(seen) == 2 and seen[1].sum() > 0
    # a section at the screen's margin may flip with the last bit of libm: at most one in a thousand
    assert (seen[0] != seen[1]).sum() <= max(1, 1e-3 * seen[1].size)
    _assert_same(fast, slow)


def _field_model(rotor_name="phase_vi"):
    from calib.corrections import CorrectionGrid
    from calib.models.bem_model import BemModel
    rotor = load_rotor(rotor_name)
    grid = CorrectionGrid(np.linspace(-4.0, 16.0, 6), np.linspace(0.3, 0.95, 5))
    return BemModel(rotor, grid, ("power", "thrust", "root_flap_moment"), BemSettings(use_tilt=False),
                    nuisance=("pitch_offset",)), grid


@pytest.mark.parametrize("seed", [0, 1])
def test_correction_field_compiled_same_as_numpy_path(seed, numpy_path, monkeypatch):
    """A calibration chain (the correction field and a pitch offset) runs the compiled root search with the
    field evaluated in C; values, roots and the exact Jacobian agree with the numpy path. Drag corrections
    down to -0.05 put some sections on the drag floor; angles of attack span the nodes and beyond."""
    from calib.bem import sections
    model, grid = _field_model()
    rng = np.random.default_rng(seed)
    p = np.zeros(len(model.parameters))
    p[:grid.n_lift] = 0.2 * rng.standard_normal(grid.n_lift)
    p[grid.n_lift:grid.n_params] = rng.uniform(-0.05, 0.02, grid.n_lift)
    p[-1] = 0.7
    rotor = model.rotor
    cond = _grid(rotor, tsr=np.linspace(1.5, 12.0, 8), pitch=np.linspace(-6.0, 25.0, 7), rpm=72.0)
    fields = []
    make = kernel.SectionKernel

    def spy(*args, **kwargs):
        out = make(*args, **kwargs)
        fields.append(out.field)
        return out

    monkeypatch.setattr(sections.kernel, "SectionKernel", spy)
    seen = []
    search = sections.lowest_roots

    def spy_search(residual, phi, fphi, lo, hi, candidates, *args, **kwargs):
        seen.append(candidates.copy())
        return search(residual, phi, fphi, lo, hi, candidates, *args, **kwargs)

    monkeypatch.setattr(sections, "lowest_roots", spy_search)
    fast = model.solve(p, cond, sensitivities=True)
    ev_fast, g_fast = model.jacobian(p, cond)
    assert fields and all(f is not None for f in fields)
    numpy_path()
    slow = model.solve(p, cond, sensitivities=True)
    ev_slow, g_slow = model.jacobian(p, cond)
    assert (slow.status == Status.CONVERGED).sum() > 20
    # the compiled screen (polar after the field) selects the sections the numpy screen selects
    assert len(seen) == 4 and seen[3].sum() > 0
    assert (seen[0] != seen[2]).sum() <= max(1, 1e-3 * seen[0].size)
    cd_floor = slow.sections["cd"] == grid.cd_floor
    assert cd_floor.any(), "no section on the drag floor: the test does not reach it"
    _assert_same(fast, slow)
    np.testing.assert_array_equal(np.isnan(ev_fast.values), np.isnan(ev_slow.values))
    np.testing.assert_allclose(ev_fast.values, ev_slow.values, rtol=1e-11, atol=0)
    scale = np.nanmax(np.abs(g_slow), axis=(0, 1))
    np.testing.assert_allclose(g_fast, g_slow, rtol=1e-9, atol=1e-10 * scale.max())


def test_compiled_jacobian_matches_central_differences(monkeypatch):
    """The compiled derivatives (forward mode in kernel.c) against central differences of the
    compiled solve, on the correction field's nodes and the pitch offset, off the drag floor."""
    from calib.bem import sections
    used = []
    compiled_pass = sections.kernel_chain.compiled_pass
    monkeypatch.setattr(sections.kernel_chain, "compiled_pass", lambda *a: used.append(1) or compiled_pass(*a))
    model, grid = _field_model()
    rng = np.random.default_rng(5)
    p = np.zeros(len(model.parameters))
    p[:grid.n_lift] = 0.05 * rng.standard_normal(grid.n_lift)
    p[grid.n_lift:grid.n_params] = 0.002
    p[-1] = 0.4
    cond = _grid(model.rotor, tsr=np.linspace(3.0, 9.0, 4), pitch=np.array([0.0, 4.0]), rpm=72.0)
    ev, G = model.jacobian(p, cond)
    assert used and np.isfinite(G).all()
    for j in (grid.node_index(1, 2), grid.node_index(3, 4), grid.n_lift + grid.node_index(2, 3), len(p) - 1):
        h = 1e-6 * max(1.0, abs(p[j]))
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        fd = (model.evaluate(up, cond).values - model.evaluate(down, cond).values) / (2 * h)
        scale = np.max(np.abs(G), axis=(0, 2))     # per channel
        np.testing.assert_allclose(G[:, :, j], fd, rtol=1e-5, atol=1e-6 * scale.max(), err_msg=str(j))
