"""The model discrepancy of a design criterion (:mod:`calib.design.discrepancy`): the low-rank basis
against the exact squared-exponential kernel, the augmented precision against generalized least
squares with the discrepancy's covariance in the noise, and what it does to a design."""

import numpy as np
import pytest

from calib.design.candidates import Envelope, generate
from calib.design.criteria import d_criterion
from calib.design.discrepancy import Discrepancy, augment, basis, parse_discrepancy
from calib.design.select import precision, select
from calib.errors import InputError

ENV = Envelope((2.0, 8.0), (-2.0, 8.0), (72.0, 72.0), (0.0, 0.0), 1.225, 5.03)


def _unit(cond):
    lam = cond.tip_speed_ratio(ENV.radius)
    return np.column_stack([(lam - 2.0) / 6.0, (cond.pitch + 2.0) / 10.0])


def _kernel(X, length):
    d2 = np.sum((X[:, None] - X[None]) ** 2, axis=-1)
    return np.exp(-0.5 * d2 / length ** 2)


def test_basis_reproduces_the_squared_exponential_kernel():
    """φ(x)ᵀφ(x') against k(x, x') = exp(-|x - x'|²/2ℓ²) on points off the inducing grid."""
    cond = generate(ENV, 13, 11)
    disc = Discrepancy(1.0, 0.25)
    phi = basis(cond, ENV, disc)
    K = _kernel(_unit(cond), 0.25)
    assert np.max(np.abs(phi @ phi.T - K)) < 0.03
    assert np.allclose(np.diag(phi @ phi.T), 1.0, atol=0.03)


def test_augmented_precision_equals_gls_with_the_discrepancy_in_the_noise():
    """The Schur complement of the augmented whitened precision on the parameters = I + Hᵀ(I + κ²K)⁻¹H,
    the information of generalized least squares with the covariance σ²(I + κ²K) (Kennedy & O'Hagan 2001),
    at points where the low-rank basis is exact (the inducing grid, spacing 1/6)."""
    rng = np.random.default_rng(3)
    disc = Discrepancy(1.5, 0.25)
    cond = generate(ENV, 7, 7)                              # the inducing grid of ℓ = 0.25 (7 per axis)
    n, npts = 3, len(cond)
    H = rng.normal(size=(npts, 1, n))
    Ha = augment(H, basis(cond, ENV, disc), disc)
    A = precision(Ha, np.arange(npts))
    Schur = A[:n, :n] - A[:n, n:] @ np.linalg.solve(A[n:, n:], A[n:, :n])
    R = np.eye(npts) + disc.scale ** 2 * _kernel(_unit(cond), 0.25)
    G = H[:, 0, :]
    assert np.allclose(Schur, np.eye(n) + G.T @ np.linalg.solve(R, G), rtol=1e-6, atol=1e-8)


def test_discrepancy_stops_repeats_and_spreads_the_points():
    """Equal sensitivities at every point: without a discrepancy every multiset is D-optimal (a repeat as
    good as a new point); with it, no point is repeated and the two points chosen are the farthest apart."""
    cond = generate(ENV, 9, 1)                              # one pitch line: λ 2…8
    H = np.ones((len(cond), 1, 1))
    disc = Discrepancy(1.0, 0.25)
    Ha = augment(H, basis(cond, ENV, disc), disc)
    crit = d_criterion()
    g = crit.gains(np.linalg.inv(precision(H, [0])), H)
    assert np.allclose(g, np.log(1.5))                       # log det 1 + 2 against 1 + 1: any point, a repeat too
    ga = crit.gains(np.linalg.inv(precision(Ha, [0])), Ha)
    assert int(np.argmax(ga)) == 8 and ga[0] < ga[1:].min()  # the far end best, the repeat worst
    two = select(d_criterion(), Ha, 2, max_repeats=2)
    assert sorted(two.design.tolist()) == [0, 8]
    four = select(d_criterion(), Ha, 4, max_repeats=4)
    assert len(set(four.design.tolist())) == 4


@pytest.mark.parametrize("text, message", [("x", "SCALE"), ("1:2:3", "SCALE"), ("-1", "scale"), ("1:0", "length")])
def test_bad_discrepancy_is_refused(text, message):
    with pytest.raises(InputError, match=message):
        parse_discrepancy(text)


def test_none_turns_it_off():
    assert parse_discrepancy("none") is None
    assert parse_discrepancy("2:0.5") == Discrepancy(2.0, 0.5)


def test_relaxed_bound_is_above_every_subset_and_tight_for_equal_candidates():
    """The continuous-relaxation bound ≥ the best of all 56 three-point subsets of 8 random candidates; for
    equal candidates every subset has log det log(1 + N h²), which the bound reaches."""
    from itertools import combinations

    from calib.design.bound import relaxed_logdet_bound

    rng = np.random.default_rng(5)
    H = rng.normal(size=(8, 2, 3))
    best = max(np.linalg.slogdet(precision(H, list(c)))[1] for c in combinations(range(8), 3))
    b = relaxed_logdet_bound(H, 3, iterations=500)
    assert b["bound"] >= best - 1e-9
    assert b["relaxed"] <= b["bound"] + 1e-12
    assert b["bound"] - best < 0.5
    same = np.full((6, 1, 1), 0.7)
    assert relaxed_logdet_bound(same, 4)["bound"] == pytest.approx(np.log(1 + 4 * 0.49), abs=2e-3)
