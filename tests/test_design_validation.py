"""The statistics of the campaign-design validation benchmarks (issue 39): the linear-Gaussian spread of a
MAP estimate along the design's directions, and the noise of a realized ranking of sensor subsets."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import bench_design as bd  # noqa: E402
import bench_design_phase_vi as bp  # noqa: E402


def test_spread_along_matches_monte_carlo_and_closed_form():
    """√(vᵀA⁻¹FA⁻¹v) against 40 000 linear MAP estimates A⁻¹Hᵀe, e ~ N(0, I); along F's eigenvectors it is
    s/(1 + s²) (closed form)."""
    rng = np.random.default_rng(1)
    H = rng.normal(size=(7, 2, 4)) * np.array([2.0, 1.0, 0.5, 0.2])
    F = np.einsum("jmn,jmk->nk", H, H)
    lam, V = np.linalg.eigh(F)
    s = np.sqrt(lam)
    got = bd._spread_along(H, V)
    np.testing.assert_allclose(got, s / (1 + s ** 2), rtol=1e-10)
    e = rng.normal(size=(40000, 7, 2))
    U = np.linalg.solve(np.eye(4) + F, np.einsum("jmn,rjm->nr", H, e)).T
    W = rng.normal(size=(4, 3))                        # any directions, not only the eigenvectors
    np.testing.assert_allclose(bd._spread_along(H, W), np.std(U @ W, axis=0), rtol=0.02)


def _real(scores_by_fold):
    """Fake leave-one-out results: nominal |error| 1 in every fold, calibrated |error| as given."""
    return [{"folds": {ch: [{"measured": 0.0, "nominal": 1.0, "predicted": float(x)} for x in row] for ch in bp.HUB}}
            for row in scores_by_fold]


def test_ranking_noise_without_noise_and_exact_permutation_p():
    """Folds that agree exactly: every resample ranks as the data do (ceiling 1); a design that ranks as the
    data has Spearman 1, whose permutation p over 5 subsets is 1/120 (the exact share of the 120 orders)."""
    true = np.array([0.3, 0.4, 0.5, 0.6, 0.7])
    q = bp.ranking_noise(_real(np.repeat(true[:, None], 6, axis=1)), true, n_boot=200, n_perm=20000)
    assert q["observed"] == pytest.approx(1.0)
    assert q["ceiling_5_95"][0] == pytest.approx(1.0)
    assert q["pick_best"] == 1.0
    assert q["p_permutation"] == pytest.approx(1 / 120, abs=0.003)
    reverse = bp.ranking_noise(_real(np.repeat(true[:, None], 6, axis=1)), true[::-1], n_boot=50, n_perm=2000)
    assert reverse["observed"] == pytest.approx(-1.0) and reverse["p_permutation"] == 1.0


def test_ranking_noise_sees_noisy_folds():
    """Folds whose errors scatter more than the subsets differ: the ceiling falls well below 1 and the
    jackknife σ of each score is near the folds' scatter over √6."""
    rng = np.random.default_rng(3)
    true = np.array([0.40, 0.42, 0.44, 0.46, 0.48])
    folds = true[:, None] * np.exp(0.4 * rng.normal(size=(5, 6)))
    q = bp.ranking_noise(_real(folds), true, n_boot=400, n_perm=2000)
    assert q["ceiling_5_95"][0] < 0.5
    sd = np.std(folds, axis=1, ddof=1) / np.sqrt(6)
    np.testing.assert_allclose(q["score_jackknife_sd"], sd, rtol=0.05)


def test_misfit_kappa_and_the_within_noise_rule():
    """κ² + 1 = the held-out mean square over σ² (here torque errors 3σ and 5σ: 17; thrust 4σ: 16; mean 16.5);
    a model as good as the noise has κ 0. A proxy that ranks as the folds do is within the noise, its reverse
    is not."""
    hub = {"folds": {"torque": [{"measured": 0.0, "predicted": 3.0}, {"measured": 0.0, "predicted": -5.0}],
                     "thrust": [{"measured": 10.0, "predicted": 2.0}]}}
    assert bp.misfit_kappa(hub, {"torque": 1.0, "thrust": 2.0}) == pytest.approx(np.sqrt(15.5))
    assert bp.misfit_kappa(hub, {"torque": 10.0, "thrust": 20.0}) == 0.0
    true = np.array([0.3, 0.4, 0.5, 0.6, 0.7])
    real = _real(true[:, None] * np.exp(0.05 * np.random.default_rng(4).normal(size=(5, 6))))
    good = bp.proxy_summary(true, true, real)
    bad = bp.proxy_summary(true[::-1], true, real)
    assert good["within_noise"] and good["pick_rank"] == 1
    assert not bad["within_noise"] and bad["pick_rank"] == 5
