"""A corrected model evaluates every point the nominal model evaluates: C_D never reaches 0.

Node bounds keep C_D,0 + ΔC_D ≥ cd_min at the nodes only; between them (a drag bucket lying
between two α nodes) and beyond them the bilinear field could take the drag to zero or below,
and the BEM refused those points (``INVALID_INPUT``). The correction field now holds the
corrected drag at min(cd_floor, C_D,0) at every section.
"""

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.bem import dual as dl
from calib.corrections import CorrectionGrid
from calib.effects.correction_field import floor_drag
from calib.errors import InputError
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions

GRID = CorrectionGrid([-4.0, 2.0, 8.0, 14.0, 20.0], [0.3, 0.6, 0.85, 1.0])


def _random_campaign(rotor, rng, n):
    lam, v, pitch = rng.uniform(2.0, 14.0, n), rng.uniform(3.0, 25.0, n), rng.uniform(-5.0, 30.0, n)
    return OperatingConditions(v, lam * v / rotor.rotor_radius * 30 / np.pi, pitch)


@pytest.mark.parametrize("seed", [9801, 9802, 9803])
def test_a_corrected_model_evaluates_every_point_the_nominal_model_evaluates(seed):
    """Random fields inside the calibration's bounds (the drag nodes near their C_D ≥ 0 bound, where
    a field between nodes goes negative) at random operating points (λ 2-14, 3-25 m/s, pitch -5 to
    30 deg, beyond the nodes' α range too)."""
    rotor = load_rotor("nrel5mw")
    model = BemModel(rotor, GRID, ("power", "thrust", "root_flap_moment"), BemSettings(use_tilt=False), ())
    p0 = np.array([q.nominal for q in model.parameters])
    lower = model.correction_field().lower_bounds(np.array([q.lower for q in model.parameters]), p0, 0.0)
    upper = np.array([q.upper for q in model.parameters])
    rng = np.random.default_rng(seed)
    cond = _random_campaign(rotor, rng, 120)
    nominal = model.evaluate(p0, cond)
    assert nominal.ok.all()
    span = np.where(np.arange(p0.size) >= GRID.n_lift, 0.02, 0.4)
    for _ in range(3):
        p = rng.uniform(lower, np.minimum(upper, lower + span))
        ev = model.evaluate(p, cond)
        assert ev.ok[nominal.ok].all(), [m for m, ok in zip(ev.messages, ev.ok) if not ok][:3]
        assert np.all(np.isfinite(ev.values))


def test_the_floor_holds_the_drag_and_leaves_the_uncorrected_polar_alone():
    cd0 = np.array([0.008, 0.008, 0.0005, 0.0005])
    cd = cd0 + np.array([0.002, -0.0075, 0.0, -0.0002])
    assert np.array_equal(floor_drag(cd, cd0, 0.001), [0.010, 0.001, 0.0005, 0.0005])
    # duals: the derivative of the held drag with respect to the correction is zero
    d = dl.Dual(cd, np.eye(4))
    out = floor_drag(d, cd0, 0.001)
    assert np.array_equal(out.v, [0.010, 0.001, 0.0005, 0.0005])
    assert np.array_equal(np.diag(out.d), [1.0, 0.0, 1.0, 0.0])
    with pytest.raises(InputError, match="cd_floor"):
        CorrectionGrid([0.0, 10.0], [0.5, 1.0], cd_floor=0.0)
    assert CorrectionGrid(**GRID.to_dict()).to_dict() == GRID.to_dict()


def test_the_exact_jacobian_agrees_with_differences_where_the_floor_holds_some_sections():
    rotor = load_rotor("nrel5mw")
    model = BemModel(rotor, GRID, ("power", "thrust"), BemSettings(use_tilt=False), ())
    p0 = np.array([q.nominal for q in model.parameters])
    p = p0.copy()
    p[GRID.n_lift:] = -0.15                      # every drag node far below the floor: the floor holds all
    p[GRID.n_lift + GRID.node_index(2, 2)] = 0.004   # but one
    cond = _random_campaign(rotor, np.random.default_rng(9804), 6)
    ev, G = model.jacobian(p, cond)
    assert ev.ok.all()
    for j in (GRID.n_lift + GRID.node_index(0, 0), GRID.n_lift + GRID.node_index(2, 2), GRID.node_index(2, 2)):
        h = 1e-6
        e = np.zeros_like(p)
        e[j] = h
        fd = (model.evaluate(p + e, cond).values - model.evaluate(p - e, cond).values) / (2 * h)
        assert np.allclose(G[:, :, j], fd, rtol=1e-5, atol=1e-6 * np.abs(ev.values).max()), j
    # where the floor holds every section a drag node reaches, that node has no effect at all
    assert (G[:, :, GRID.n_lift + GRID.node_index(0, 0)] == 0.0).all(axis=1).any()
