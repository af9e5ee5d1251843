"""The correction field: hat functions, partition of unity, slopes, parameters."""

import numpy as np
import pytest

from calib.corrections import CorrectionGrid, hat_weights
from calib.errors import InputError
from calib.models.base import OperatingConditions
from calib.models.bem_model import BemModel
from synthetic import synthetic_rotor


def test_partition_of_unity_inside_and_ramp_outside():
    nodes = np.array([-4.0, 0.0, 6.0, 14.0])
    x = np.linspace(-4.0, 14.0, 181)
    _, w, _ = hat_weights(x, nodes)
    np.testing.assert_allclose(w.sum(-1), 1.0, atol=1e-14)
    _, w_out, _ = hat_weights(np.array([-6.0, -8.0, -9.0, 18.0, 22.0, 30.0]), nodes)
    np.testing.assert_allclose(w_out.sum(-1), [0.5, 0.0, 0.0, 0.5, 0.0, 0.0], atol=1e-14)


def test_field_is_bilinear_interpolation_of_nodal_values():
    grid = CorrectionGrid([0.0, 10.0, 20.0], [0.2, 0.6, 1.0])
    rng = np.random.default_rng(0)
    p = rng.normal(size=grid.n_params)
    # at the nodes the field equals the nodal value
    for i, a in enumerate(grid.alpha_nodes_deg):
        for j, e in enumerate(grid.eta_nodes):
            dcl, dcd, _, _ = grid.evaluate(p, a, e)
            assert dcl == pytest.approx(p[grid.node_index(i, j)])
            assert dcd == pytest.approx(p[grid.n_lift + grid.node_index(i, j)])
    # slope in alpha against central differences, away from nodes
    a, e = np.array([3.3, 14.1, 25.0]), np.array([0.35, 0.9, 0.5])
    h = 1e-6
    fd = (grid.evaluate(p, a + h, e)[0] - grid.evaluate(p, a - h, e)[0]) / (2 * h)
    np.testing.assert_allclose(grid.evaluate(p, a, e)[2], fd, rtol=1e-7, atol=1e-9)


def test_parameters_order_and_metadata():
    grid = CorrectionGrid([0.0, 8.0], [0.5, 1.0], cl_scale=0.05, cd_scale=0.005)
    params = grid.parameters()
    assert [q.kind for q in params] == ["lift_correction"] * 4 + ["drag_correction"] * 4
    assert params[grid.node_index(1, 0)].alpha_deg == 8.0 and params[grid.node_index(1, 0)].eta == 0.5
    assert params[0].scale == 0.05 and params[4].scale == 0.005


@pytest.mark.parametrize("nodes", [[0.0], [0.0, 0.0, 1.0], [1.0, 0.0], [0.0, np.nan]])
def test_bad_nodes_are_rejected_with_the_field_named(nodes):
    with pytest.raises(InputError, match="alpha_nodes_deg"):
        CorrectionGrid(nodes, [0.0, 1.0])


def test_bem_model_bad_inputs_name_the_problem():
    rotor = synthetic_rotor()
    with pytest.raises(InputError, match="unknown channel 'pwr'"):
        BemModel(rotor, channels=("pwr",))
    with pytest.raises(InputError, match="outside the blade"):
        BemModel(rotor, channels=("cn@0.01",))
    with pytest.raises(InputError, match="unknown nuisance"):
        BemModel(rotor, nuisance=("gain",))
    model = BemModel(rotor, CorrectionGrid([0.0, 10.0], [0.5, 1.0]))
    cond = OperatingConditions([8.0], [15.0], [0.0])
    with pytest.raises(InputError, match="expected 10 parameter values"):
        model.evaluate(np.zeros(3), cond)
    p = np.zeros(10)
    p[-1] = np.nan
    with pytest.raises(InputError, match="wind_scale"):
        model.evaluate(p, cond)
