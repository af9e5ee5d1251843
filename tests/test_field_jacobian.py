"""The fine-grid sensitivities of the aliasing term projected from the estimate's solve
(``BemModel.field_jacobian``) against a solve of the model rebuilt on the fine grid, and the cases
where the projection is refused (another parameter vector or conditions, a section beyond the grid,
another drag floor)."""

import dataclasses

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.corrections import CorrectionGrid
from calib.models.bem_model import BemModel
from calib.parametrizations.aliasing import fine_sensitivities, refined_grid
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions


def _case(n_sectors_settings):
    rotor = load_rotor("phase_vi")
    grid = CorrectionGrid(np.linspace(-4.0, 16.0, 6), np.linspace(0.3, 1.0, 5))
    model = BemModel(rotor, grid, ("power", "thrust", "root_flap_moment"), n_sectors_settings,
                     nuisance=("pitch_offset",))
    rng = np.random.default_rng(2)
    p = np.zeros(len(model.parameters))
    p[:grid.n_lift] = 0.05 * rng.standard_normal(grid.n_lift)
    p[grid.n_lift:grid.n_params] = 0.002
    p[-1] = 0.4
    lam, beta = np.meshgrid(np.linspace(3.0, 9.0, 5), np.array([-2.0, 1.0, 4.0]), indexing="ij")
    wind = 72.0 * np.pi / 30 * rotor.rotor_radius / lam.ravel()
    cond = OperatingConditions(wind, np.full(wind.size, 72.0), beta.ravel())
    return model, grid, p, cond


@pytest.mark.parametrize("settings", [BemSettings(use_tilt=False), BemSettings(shear_exponent=0.2)],
                         ids=["axisymmetric", "sectors"])
def test_projected_fine_sensitivities_equal_a_solve_on_the_fine_grid(settings):
    """W from the kept section derivatives equals W from the model rebuilt on the refined grid and
    solved at the interpolated nodal values (another code path: another field table, another solve)
    to 1e-8 of each column's largest entry; with several sectors too when every loaded section is
    inside the fine grid, else the projection is refused and the solve path gives the same W."""
    model, grid, p, cond = _case(settings)
    ev, _ = model.jacobian(p, cond)
    a, e = model.correction_field().seen(ev)
    sigma = np.full((len(cond), 3), 2.0)
    fine = refined_grid(grid, a, e)
    used = model.field_jacobian(fine, p, cond)
    projected = fine_sensitivities(model, p, cond, sigma, [0, 1, 2], ev.ok, a, e)
    other = dataclasses.replace(cond)                   # equal conditions, another object: no projection
    assert model.field_jacobian(fine, p, other) is None
    solved = fine_sensitivities(model, p, other, sigma, [0, 1, 2], ev.ok, a, e)
    assert projected.W.shape == solved.W.shape and projected.n_fine == solved.n_fine == fine.n_lift
    scale = np.maximum(np.abs(solved.W).max(axis=0), 1e-300)
    assert np.abs(solved.W).max() > 0
    np.testing.assert_array_less(np.abs(projected.W - solved.W) / scale, 1e-8)
    if settings.use_tilt is False:
        assert used is not None              # the axisymmetric case takes the projection


def test_the_projection_is_refused_where_it_would_not_be_exact():
    model, grid, p, cond = _case(BemSettings(use_tilt=False))
    ev, _ = model.jacobian(p, cond)
    a, e = model.correction_field().seen(ev)
    fine = refined_grid(grid, a, e)
    assert model.field_jacobian(fine, p, cond) is not None
    q = p.copy()
    q[0] += 1e-3
    assert model.field_jacobian(fine, q, cond) is None                      # not the kept solve
    narrow = CorrectionGrid(np.linspace(0.0, 5.0, 4), fine.eta_nodes, cl_bound=10.0, cd_bound=10.0)
    assert model.field_jacobian(narrow, p, cond) is None                    # sections beyond its α nodes
    short = CorrectionGrid(fine.alpha_nodes_deg, np.linspace(0.3, 0.95, 5), cl_bound=10.0, cd_bound=10.0)
    assert model.field_jacobian(short, p, cond) is None                     # the tip sections beyond its η
    floor = CorrectionGrid(fine.alpha_nodes_deg, fine.eta_nodes, cl_bound=10.0, cd_bound=10.0,
                           cd_floor=2 * grid.cd_floor)
    assert model.field_jacobian(floor, p, cond) is None                     # another drag floor


def test_a_pickled_model_leaves_the_kept_solve_behind():
    import pickle

    model, grid, p, cond = _case(BemSettings(use_tilt=False))
    before = len(pickle.dumps(model))
    model.jacobian(p, cond)
    copy = pickle.loads(pickle.dumps(model))
    assert len(pickle.dumps(model)) == before and getattr(copy, "_last_jacobian", None) is None
    np.testing.assert_array_equal(copy.evaluate(p, cond).values, model.evaluate(p, cond).values)


def test_a_recorded_model_passes_the_projection_through(tmp_path):
    """`calib run` wraps the model in a history record: the projection must reach through it (the same
    W as the bare model), and a record answered from the history (no solve behind it) refuses it."""
    from calib.history import open_history
    from calib.models.recorded_model import RecordedModel

    model, grid, p, cond = _case(BemSettings(use_tilt=False))
    history = open_history(tmp_path, {"command": "run", "inputs": {"workflow file": "a" * 64}}, resume=False)
    rec = RecordedModel(model, history, "test")
    ev, _ = rec.jacobian(p, cond)
    a, e = model.correction_field().seen(ev)
    fine = refined_grid(grid, a, e)
    through = rec.field_jacobian(fine, p, cond)
    assert through is not None
    np.testing.assert_array_equal(through[1], model.field_jacobian(fine, p, cond)[1])
    fresh, _, _, cond2 = _case(BemSettings(use_tilt=False))
    replay = RecordedModel(fresh, history, "test")
    replay.jacobian(p, cond2)                            # answered from the record: the model did not solve
    assert replay.n_replayed == 1 and replay.field_jacobian(fine, p, cond2) is None
