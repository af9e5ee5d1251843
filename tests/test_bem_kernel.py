"""The compiled root search (calib.bem.kernel) against the numpy path it replaces.

The kernel runs the same bracket, iteration and residual, in the same order of operations:
the same number of iterations and roots per section, values equal to the last bits of
sin, cos, exp and acos (libm against numpy's loops).
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


def _assert_same(fast, slow):
    np.testing.assert_array_equal(fast.status, slow.status)
    for name in ("iterations", "n_roots"):
        np.testing.assert_array_equal(fast.sections[name], slow.sections[name], err_msg=name)
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
    np.testing.assert_array_equal(seen[0], seen[1])
    _assert_same(fast, slow)
