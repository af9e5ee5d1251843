"""Every derivative of BemModel.jacobian against central finite differences."""

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.corrections import CorrectionGrid
from calib.models.base import OperatingConditions
from calib.types import nominal_vector
from calib.models.bem_model import BemModel
from synthetic import synthetic_rotor

CHANNELS = ("power", "thrust", "torque", "root_flap_moment", "root_edge_moment", "hub_flap_moment",
            "cn@0.35", "ct@0.6", "fn@0.8", "ft@0.95")


def _fd_check(model, p, cond, step_rel=1e-4):
    ev, G = model.jacobian(p, cond)
    assert ev.n_failed == 0, ev.failure_summary()
    worst = 0.0
    # floor: 1e-5 of the channel's largest sensitivity (scaled by the parameter scale), so
    # derivatives at round-off level are not compared relative to themselves
    scales = np.array([max(q.scale, 1e-3) for q in model.parameters])
    floor = 1e-5 * np.abs(G * scales).max(axis=(0, 2))
    for j, par in enumerate(model.parameters):
        h = step_rel * max(par.scale, 1e-3)
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (model.evaluate(pp, cond).values - model.evaluate(pm, cond).values) / (2 * h)
        scale = np.maximum(np.maximum(np.abs(fd).max(axis=0), np.abs(G[:, :, j]).max(axis=0)),
                           floor / max(par.scale, 1e-3))
        ok = scale > 0
        err = np.abs(fd - G[:, :, j])[:, ok] / scale[ok]
        worst = max(worst, float(err.max()) if err.size else 0.0)
        assert err.size == 0 or err.max() < 2e-5, (par.name, err.max(axis=0))
    return worst


@pytest.mark.parametrize("tilt,yaw,shear", [(0.0, 0.0, 0.0), (5.0, 12.0, 0.2)])
def test_jacobian_matches_central_differences(tilt, yaw, shear):
    rotor = synthetic_rotor(n_stations=12, precone_deg=2.5, tilt_deg=tilt, precurve_tip=-1.0)
    # nodes placed off the α values the sections see, so the hat kinks do not spoil the differences
    grid = CorrectionGrid([-7.3, -1.1, 4.9, 11.3, 17.9], [0.05, 0.37, 0.71, 1.0])
    model = BemModel(rotor, grid, CHANNELS, BemSettings(shear_exponent=shear))
    rng = np.random.default_rng(7)
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = rng.normal(0, 0.05, grid.n_lift)
    p[grid.n_lift:grid.n_params] = np.abs(rng.normal(0, 0.002, grid.n_lift))
    p[-2], p[-1] = 0.4, 1.03
    cond = OperatingConditions([5.5, 8.0, 11.0, 16.0], [12.0, 14.0, 16.0, 16.0], [0.5, 0.0, 2.0, 9.0], 1.225,
                               [yaw, 0.0, -yaw, yaw])
    worst = _fd_check(model, p, cond)
    assert worst < 2e-5


def test_jacobian_shape_and_nominal_zero_correction():
    rotor = synthetic_rotor()
    grid = CorrectionGrid([0.0, 10.0], [0.5, 1.0])
    model = BemModel(rotor, grid, ("power",), nuisance=())
    assert len(model.parameters) == grid.n_params
    cond = OperatingConditions([8.0], [15.0], [0.0])
    ev, G = model.jacobian(np.zeros(grid.n_params), cond)
    assert G.shape == (1, 1, grid.n_params)
    # more lift at the outboard nodes must raise power below rated (physics sign check)
    assert G[0, 0, grid.node_index(1, 1)] > 0 or G[0, 0, grid.node_index(0, 1)] > 0
    # more drag lowers power
    assert G[0, 0, grid.n_lift + grid.node_index(0, 1)] < 0


def test_jacobian_at_a_point_with_several_roots():
    """Phase VI at 20 m/s keeps the smallest-φ of three roots at r/R = 0.994; the implicit-function
    derivatives hold at that root (the perturbed evaluations keep the same root)."""
    from calib.rotor.library import load_rotor
    rotor = load_rotor("phase_vi")
    model = BemModel(rotor, None, ("power", "thrust", "root_flap_moment", "ft@0.95"), BemSettings(use_tilt=False))
    cond = OperatingConditions([20.0, 10.0], [72.08, 72.11], [3.0, 3.0], 1.22)
    ev = model.evaluate(nominal_vector(model.parameters), cond)
    assert ev.extras["multiple_roots"].tolist() == [True, False]
    worst = _fd_check(model, nominal_vector(model.parameters), cond)
    assert worst < 2e-5
