"""The figures of ``benchmarks/bench_powercurve.py`` that its tables state (issue 41): where the 3× floor
applies and the model discrepancy against the realized one, on hand-made inputs."""

import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))


def _truth(effect_power, control_power, loads):
    from oof_battery import campaign
    from calib.powercurve import iec_bins

    v = iec_bins(3.0, 25.0, 0.5)
    conv = [True] * v.size

    def ds(p):
        d = {campaign.CCBLADE_KEYS[c]: list(loads[:, j]) for j, c in enumerate(campaign.CHANNELS)}
        d["curve"] = {"power": list(p), "converged": conv}
        return d
    return {"data_sets": {"control": ds(control_power), "effect": ds(effect_power)}}


def test_the_floor_applies_where_the_effect_moves_power_beyond_the_noise():
    """The noise σ is 1 % of the RMS power over the points (``campaign.noise_sigma``); bins whose power the
    effect changes by more than σ are counted, the others not."""
    from bench_powercurve import effect_vs_noise
    from oof_battery import campaign
    from calib.powercurve import iec_bins

    v = iec_bins(3.0, 25.0, 0.5)
    loads = np.tile([[2.0e6, 1.0, 1.0, 1.0]], (63, 1))
    loads[::2, 0] = 1.0e6              # RMS power √((4 + 1)/2)·10⁶ to within the odd count
    sigma = 0.01 * np.sqrt(np.mean(loads[:, 0] ** 2))
    p0 = np.full(v.size, 3.0e6)
    p1 = p0.copy()
    p1[v == 7.0] += 2.5 * sigma        # above the noise
    p1[v == 8.0] -= 0.5 * sigma        # below it
    out = effect_vs_noise(_truth(p1, p0, loads), ["control", "effect"])["effect"]
    assert out["noise_sigma_w"] == pytest.approx(sigma, rel=1e-12)
    assert campaign.CHANNELS[0] == "power"
    assert out["bins_above"] == 1 and out["above_m_s"] == [7.0, 7.0] and out["floor_applies"]
    assert out["max_ratio"] == pytest.approx(2.5, rel=1e-9) and out["max_ratio_at_m_s"] == 7.0
    out = effect_vs_noise(_truth(p0 + 0.9 * sigma, p0, loads), ["effect"])["effect"]
    assert out["bins_above"] == 0 and not out["floor_applies"] and out["above_m_s"] is None


def test_the_discrepancy_summary_against_a_gaussian_monte_carlo():
    """Realized discrepancies drawn from N(μ, Σ) as the process states: realized/stated and the
    standardized rms near 1; drawn at a quarter of the stated spread, realized/stated near ¼."""
    from bench_powercurve import _discrepancy_summary

    rng = np.random.default_rng(3)
    n = 4000
    mu = rng.normal(0.0, 30.0, n)
    sd = rng.uniform(20.0, 40.0, n)
    real = mu + sd * rng.standard_normal(n)
    checks = [{"realized_mwh": r, "mean_mwh": m, "conditional_sd_mwh": s, "amplitude": 0.02, "length": 0.3}
              for r, m, s in zip(real, mu, sd)]
    s = _discrepancy_summary(checks)
    assert s["standardized_rms"] == pytest.approx(1.0, abs=0.04)
    # E[r²/(μ² + s²)] = 1 when r ~ N(μ, s²)
    assert s["realized_over_stated_rms"] == pytest.approx(1.0, abs=0.05)
    assert s["stated_rms_mwh"] == pytest.approx(np.sqrt(np.mean(mu ** 2 + sd ** 2)), rel=1e-12)
    small = [dict(c, realized_mwh=0.25 * np.sqrt(c["mean_mwh"] ** 2 + c["conditional_sd_mwh"] ** 2)
                  * rng.standard_normal()) for c in checks]
    assert _discrepancy_summary(small)["realized_over_stated_rms"] == pytest.approx(0.25, abs=0.02)
    assert _discrepancy_summary([]) is None
