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
