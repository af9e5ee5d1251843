"""Choosing k optional sensor groups (:mod:`calib.design.groups`): the held-out prediction variance against
the Gaussian conditional in data space, and the D_s value against generalized least squares."""

from itertools import combinations

import numpy as np
import pytest

from calib.design.candidates import Envelope, generate
from calib.design.discrepancy import Discrepancy, augment, basis
from calib.design.groups import subset_heldout_error, subset_scores, subset_sequential
from calib.design.sensors import SensorGroup
from calib.errors import InputError

ENV = Envelope((2.0, 8.0), (0.0, 6.0), (72.0, 72.0), (0.0, 0.0), 1.225, 5.03)


class Linear:
    """A linear design problem: fixed whitened blocks per point, channels a, b, c, d."""

    def __init__(self, H):
        self.H = H
        self.channels = ["a", "b", "c", "d"]
        self.groups = [SensorGroup("hub", ("a",)), SensorGroup("s1", ("b",)), SensorGroup("s2", ("c",)),
                       SensorGroup("s3", ("d",))]
        self.envelope = ENV

    def blocks(self, conditions):
        return self.H, np.ones(len(self.H), bool)


def test_heldout_variance_and_ds_against_data_space_formulas():
    rng = np.random.default_rng(11)
    cond = generate(ENV, 3, 2)                                    # 6 points, one fold each
    H = rng.normal(size=(6, 4, 3))
    disc = Discrepancy(0.8, 0.4)
    pr = Linear(H)
    scores = subset_scores(pr, cond, 2, always=["hub"], targets=["a"], discrepancy=disc, leave_out="point")
    assert [s["groups"] for s in scores] == [list(c) for c in combinations(["s1", "s2", "s3"], 2)]
    Ha = augment(H, basis(cond, ENV, disc), disc)
    for s in scores:
        rows = [pr.channels.index(c) for c in s["channels"]]
        # y = Ha w + ε, w ~ N(0, I), ε ~ N(0, I): the predictive variance of the true response at f from the others
        var = []
        for f in range(6):
            o = [j for j in range(6) if j != f]
            Ho = Ha[o][:, rows, :].reshape(-1, Ha.shape[-1])
            c = Ha[f, [0], :]
            S_oo = Ho @ Ho.T + np.eye(len(Ho))
            var.append(float((c @ c.T - c @ Ho.T @ np.linalg.solve(S_oo, Ho @ c.T))[0, 0]))
        assert s["heldout_variance"] == pytest.approx(np.mean(var), rel=1e-9)
        # D_s: the parameters' information with the discrepancy in the noise covariance
        P = H[:, rows, :].reshape(-1, 3)
        D = (Ha[:, rows, 3:]).reshape(-1, Ha.shape[-1] - 3)
        R = np.eye(len(P)) + D @ D.T
        assert s["logdet"] == pytest.approx(np.linalg.slogdet(np.eye(3) + P.T @ np.linalg.solve(R, P))[1], rel=1e-9)


def test_a_group_that_carries_the_parameters_ranks_first():
    """Channel c alone sees the parameters the target a depends on: it has the smallest held-out variance."""
    H = np.zeros((6, 4, 2))
    H[:, 0, :] = [0.3, 0.3]
    H[:, 1, 0] = 0.01
    H[:, 2, :] = [3.0, 3.0]
    H[:, 3, 1] = 0.5
    cond = generate(ENV, 3, 2)
    scores = subset_scores(Linear(H), cond, 1, always=["hub"], targets=["a"])
    best = min(scores, key=lambda s: s["heldout_variance"])
    assert best["groups"] == ["s2"] and max(scores, key=lambda s: s["logdet"])["groups"] == ["s2"]


@pytest.mark.parametrize("kw, message", [({"k": 4}, "k must be"), ({"k": 1, "always": ["taps"]}, "not among"),
                                         ({"k": 1, "targets": ["torque"]}, "target channel")])
def test_bad_choices_are_refused(kw, message):
    with pytest.raises(InputError, match=message):
        subset_scores(Linear(np.ones((6, 4, 2))), generate(ENV, 3, 2), **{"always": ["hub"], **kw})


def test_heldout_error_of_the_calibration_without_discrepancy_against_monte_carlo():
    """Draw w, b, ε; calibrate without the discrepancy (ŵ = A⁻¹Hᵀy) on the other points; the mean squared
    error of the prediction at the point left out against the true response (model + discrepancy)."""
    rng = np.random.default_rng(12)
    cond = generate(ENV, 3, 2)
    H = rng.normal(size=(6, 4, 3))
    disc = Discrepancy(1.5, 0.4)
    pr = Linear(H)
    scores = subset_heldout_error(pr, cond, 1, always=["hub"], targets=["a"], discrepancy=disc, leave_out="point")
    Ha = augment(H, basis(cond, ENV, disc), disc)
    n_draw = 40000
    w = rng.normal(size=(n_draw, Ha.shape[-1]))
    eps = rng.normal(size=(n_draw, 6, 4))
    truth = np.einsum("jmi,di->djm", Ha, w)                           # true response (draws, points, channels)
    Y = truth + eps
    for s in scores:
        rows = [pr.channels.index(c) for c in s["channels"]]
        err = []
        for f in range(6):
            o = [j for j in range(6) if j != f]
            Ho = H[o][:, rows, :].reshape(-1, 3)
            w_hat = np.linalg.solve(np.eye(3) + Ho.T @ Ho, Ho.T @ Y[:, o][:, :, rows].reshape(n_draw, -1).T).T
            err.append(np.mean((w_hat @ H[f, 0] - truth[:, f, 0]) ** 2))
        assert s["heldout_error"] == pytest.approx(np.mean(err), rel=0.03)
        assert s["bias"] > 0.1 * s["variance"]
    plain = subset_heldout_error(pr, cond, 1, always=["hub"], targets=["a"], leave_out="point")
    same = subset_scores(pr, cond, 1, always=["hub"], targets=["a"], leave_out="point")
    for p, q in zip(plain, same):
        assert p["bias"] == 0.0 and p["heldout_error"] == pytest.approx(q["heldout_variance"], rel=1e-9)


def test_sequential_target_variance_against_gaussian_conditioning():
    """The targets' model output after the optional group's data, from the prior N(0, I) of the whitened
    parameters: the Gaussian conditional in data space, the group's discrepancy in its noise covariance."""
    rng = np.random.default_rng(13)
    cond = generate(ENV, 3, 2)
    H = rng.normal(size=(6, 4, 3))
    disc = Discrepancy(0.7, 0.4)
    pr = Linear(H)
    scores = subset_sequential(pr, cond, 2, always=["hub"], targets=["a"], discrepancy=disc)
    Ha = augment(H, basis(cond, ENV, disc), disc)
    C = H[:, 0, :]
    for s in scores:
        assert "a" not in s["channels"]
        rows = [pr.channels.index(c) for c in s["channels"]]
        P = H[:, rows, :].reshape(-1, 3)
        D = Ha[:, rows, 3:].reshape(len(P), -1)
        S = P @ P.T + D @ D.T + np.eye(len(P))
        cov = C @ C.T - C @ P.T @ np.linalg.solve(S, P @ C.T)
        assert s["target_variance"] == pytest.approx(np.trace(cov) / 6, rel=1e-9)
