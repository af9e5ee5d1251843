"""Air density and wind-speed normalization against hand computations of IEC 61400-12-1's formulas."""

import numpy as np
import pytest

from calib.scada import air_density, normalized_wind_speed, vapour_pressure


def test_dry_air_at_standard_conditions_is_1_225():
    # 101325 / (287.05 * 288.15) = 101325 / 82713.4575 = 1.225012
    assert air_density(288.15, 101325.0) == pytest.approx(1.225012, rel=1e-6)


def test_humid_air_by_hand():
    # T = 293.15 K, B = 1000 hPa, φ = 0.5:
    # P_w = 2.05e-5 exp(0.0631846 * 293.15) = 2.05e-5 exp(18.52257) = 2269.87 Pa
    # ρ = (100000/287.05 − 0.5 * 2269.87 * (1/287.05 − 1/461.5)) / 293.15
    #   = (348.3714 − 1134.94 * 0.00131690) / 293.15 = (348.3714 − 1.49460) / 293.15 = 1.183274
    assert vapour_pressure(293.15) == pytest.approx(2269.87, rel=1e-5)
    assert air_density(293.15, 1.0e5, 0.5) == pytest.approx(1.183274, rel=1e-5)
    assert air_density(293.15, 1.0e5, 0.5) < air_density(293.15, 1.0e5, 0.0)   # humid air is lighter


def test_normalization_to_the_reference_density():
    # 8 m/s at 1.1 kg/m³: 8 (1.1/1.225)^(1/3) = 7.71807 m/s
    assert normalized_wind_speed(8.0, 1.1) == pytest.approx(7.71807, rel=1e-5)
    v = np.array([5.0, 10.0])
    assert np.allclose(normalized_wind_speed(v, 1.225), v)


def test_against_openoa_compute_air_density():
    # openoa 3.2 utils.met_data_processing.compute_air_density(T, B, φ) at (293.15 K, 1000 hPa, 0.5) and
    # (268.15 K, 950 hPa, 0.9), computed with openoa 3.2: the same formula with R₀ = 287.058 J/(kg K), where
    # IEC 61400-12-1 writes 287.05, so the two differ by 287.058/287.05 − 1 = 2.8e-5
    openoa = np.array([1.1832413597076232, 1.2321062231803444])
    mine = air_density([293.15, 268.15], [1.0e5, 0.95e5], [0.5, 0.9])
    assert np.allclose(mine, openoa, rtol=3.0e-5)
    assert not np.allclose(mine, openoa, rtol=1.0e-6)


@pytest.mark.parametrize("t, b, phi, st, sb, sphi", [
    (288.15, 101325.0, 0.0, 1.0, 300.0, 0.0),       # dry air: σ_T 1 K, σ_B 3 hPa
    (303.15, 98000.0, 0.8, 0.5, 100.0, 0.05),      # warm humid air: the humidity term matters
])
def test_density_sigma_against_monte_carlo(t, b, phi, st, sb, sphi):
    """σ_ρ by sensitivity factors against the sample σ of ρ over 200 000 draws of the sensors' errors
    (standard error of a sample σ: 0.16 %), and against the dry-air closed form
    σ_ρ/ρ = √((σ_T/T)² + (σ_B/B)²)."""
    from calib.scada import air_density_sigma
    rng = np.random.default_rng(11)
    n = 200_000
    draws = air_density(t + st * rng.standard_normal(n), b + sb * rng.standard_normal(n),
                        phi + sphi * rng.standard_normal(n))
    sigma = air_density_sigma(t, b, st, sb, phi, sphi)
    assert sigma == pytest.approx(draws.std(ddof=1), rel=0.01)
    if phi == 0.0:
        assert sigma / air_density(t, b) == pytest.approx(np.hypot(st / t, sb / b), rel=1e-12)
