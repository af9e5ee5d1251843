"""Fast checks of the lifting-line truth code (``benchmarks/lifting_line.py``) against closed forms."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

import lifting_line as ll  # noqa: E402


def test_straight_segment_matches_closed_form():
    """Finite segment on the z axis: |u| = Γ/(4π h) (cos θ₁ − cos θ₂), azimuthal.

    Katz & Plotkin 2001, ch. 2.
    """
    a = np.array([[0.0, 0.0, -1.0]])
    b = np.array([[0.0, 0.0, 2.0]])
    pts = np.array([[0.5, 0.0, 0.0], [0.0, 3.0, 1.0], [2.0, 2.0, 4.0]])
    u = ll.segment_velocity(pts, a, b, 1e-9)[:, 0, :]
    for p, v in zip(pts, u):
        h = math.hypot(p[0], p[1])
        cos1 = (p[2] - a[0, 2]) / math.hypot(h, p[2] - a[0, 2])
        cos2 = (p[2] - b[0, 2]) / math.hypot(h, p[2] - b[0, 2])
        expected = (cos1 - cos2) / (4.0 * math.pi * h)
        e_theta = np.array([-p[1], p[0], 0.0]) / h          # right-hand rule about +z
        assert v @ e_theta == pytest.approx(expected, rel=1e-9)
        assert abs(v[2]) < 1e-14


def test_core_removes_singularity_and_matches_vatistas():
    """On the line the velocity is zero; at h = r_c the Vatistas n = 2 factor is 1/√2 of the free vortex."""
    a, b = np.array([[0.0, 0.0, -1e4]]), np.array([[0.0, 0.0, 1e4]])
    on_line = ll.segment_velocity(np.array([[0.0, 0.0, 0.3]]), a, b, 0.1)
    assert np.all(np.isfinite(on_line)) and np.allclose(on_line, 0.0)
    u = ll.segment_velocity(np.array([[0.1, 0.0, 0.0]]), a, b, 0.1)[0, 0]
    assert np.linalg.norm(u) == pytest.approx(1.0 / (2 * math.pi * 0.1) / math.sqrt(2.0), rel=1e-6)


def test_semi_infinite_helix_of_many_turns_gives_cylinder_induction():
    """Dense helical tip vortices ≈ a vortex cylinder: axial velocity γ/2 on the axis at the rotor plane.

    B filaments of circulation Γ at radius R, pitch h per turn: sheet strength γ = B Γ / h; the
    semi-infinite cylinder induces γ/2 (times L/√(L² + R²) when truncated at length L) on the axis.
    """
    nb, radius, pitch, gamma = 3, 1.0, 0.2, 1.0
    settings = ll.LiftingLineSettings(steps_per_revolution=72, near_wake_refinement=1, wake_length_diameters=20.0)
    psi = ll.wake_angles(settings.wake_length_diameters * 2 * radius / (pitch / (2 * math.pi)), 72, 1)
    u = 0.0
    for k in range(nb):
        th = 2 * math.pi * k / nb
        pts = np.column_stack([pitch / (2 * math.pi) * psi, radius * np.cos(th - psi), radius * np.sin(th - psi)])
        u += ll.segment_velocity(np.zeros((1, 3)), pts[:-1], pts[1:], 1e-3).sum(axis=1)[0] * gamma
    length = psi[-1] * pitch / (2 * math.pi)
    expected = nb * gamma / pitch / 2.0 * length / math.hypot(length, radius)
    # wake shed backward from a rotor turning about +x: it induces −x (slows the flow) on the axis
    assert -u[0] == pytest.approx(expected, rel=2e-3)


def test_design_point_converges_and_is_near_bem_level():
    """NREL 5-MW design point, coarse: converged, C_P in the range of the rotor's design (0.45 … 0.52)."""
    rotor = ll.load_nrel5mw_rigid()
    blade = ll.blade_from_rotor_dict(rotor)
    radius = float(rotor["rotor_radius"])
    v = 11.4
    rpm = 7.5 * v / radius * 30 / math.pi
    s = ll.LiftingLineSettings(n_panels=16, wake_length_diameters=3.0, steps_per_revolution=24)
    res = ll.solve_point(blade, v, rpm, 0.0, s, radius)
    cp = res.power / (0.5 * 1.225 * math.pi * radius ** 2 * v ** 3)
    assert res.status == ll.CONVERGED, res.message
    assert 0.45 < cp < 0.52
    assert res.torque * rpm * math.pi / 30 == pytest.approx(res.power)
    assert 0.28 < res.mean_axial_induction < 0.36
