"""The experiment of ``benchmarks/bench_eiv_marginal.py`` (issue 40): its campaigns are the bench's where
they say so, its readings carry the stated errors, its two-point mean is exact for cubics, and the
prototype's Jacobian is the derivative of its outputs."""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))


@pytest.fixture(scope="module")
def field():
    import bench_eiv

    return bench_eiv.setup("field")


def test_the_classical_campaign_is_the_bench_eiv_one(field):
    from bench_eiv_marginal import campaign
    from calib.calibration.eiv_campaign import synthesize_campaign

    _, truth, pt, _, spec, _ = field
    ref, ref_true = synthesize_campaign(truth, pt, spec, 4003)
    m, true = campaign(truth, pt, spec, 4003)
    # exact on purpose: the same draws through the same code in one process (the bench's classical campaign IS
    # synthesize_campaign's), so any difference is a different campaign, not round-off
    np.testing.assert_array_equal(m.values, ref.values)
    np.testing.assert_array_equal(true.wind_speed, ref_true.wind_speed)
    for name in ("wind_speed", "rotor_speed", "pitch", "air_density"):
        np.testing.assert_allclose(getattr(m.conditions, name), getattr(ref.conditions, name), rtol=1e-13, atol=1e-12)
    for name in ("wind_speed", "pitch"):
        np.testing.assert_allclose(m.condition_sigma[name], ref.condition_sigma[name], rtol=1e-13)


def test_centred_readings_hold_the_truth_at_the_stated_error(field):
    """Truth = reading − error: (reading − truth)/σ_stated is standard normal over 600 records, in the
    model's frame (the anemometer's scale and the pitch offset undone)."""
    from bench_eiv_marginal import campaign

    _, truth, pt, _, spec, _ = field
    zv, zb = [], []
    for seed in range(4000, 4005):
        m, true = campaign(truth, pt, spec, seed, readings="centred")
        v_read = m.conditions.wind_speed / spec.anemometer_scale
        zv.append((v_read - true.wind_speed) / (m.condition_sigma["wind_speed"] / spec.anemometer_scale))
        zb.append((m.conditions.pitch + spec.pitch_offset - true.pitch) / m.condition_sigma["pitch"])
    for z in (np.concatenate(zv), np.concatenate(zb)):
        assert abs(z.mean()) < 4.0 / np.sqrt(z.size) and 0.85 < z.std() < 1.15


def test_the_two_point_mean_is_exact_for_cubics():
    """E[(u + e)³] − u³ = 3 u σ² for e ~ N(0, σ²), in wind speed and pitch at once."""
    from eiv_mean_model import mean_correction
    from calib.types import OperatingConditions

    u = OperatingConditions(np.array([5.0, 9.0, 14.0]), np.full(3, 10.0), np.array([0.0, 1.0, 6.0]), np.full(3, 1.2))
    sigma = np.array([[0.15, 0.2], [0.27, 0.2], [0.42, 0.1]])

    def f(c):
        return 2.0 * c.wind_speed ** 3 - 0.5 * c.pitch ** 3 + c.wind_speed * c.rotor_speed

    values, w = mean_correction(f, u, sigma)
    c = sum(wi * v for wi, v in zip(w, values)) - w.sum() * f(u)
    np.testing.assert_allclose(c, 2.0 * 3 * u.wind_speed * sigma[:, 0] ** 2 - 0.5 * 3 * u.pitch * sigma[:, 1] ** 2,
                               rtol=1e-10, atol=1e-12)


def test_the_prototype_jacobian_is_the_derivative_of_its_outputs(field):
    """MeanCorrectedModel's G against central differences of its own outputs (a field node, the wind
    scale and the pitch offset), and its outputs above the model's where power is convex in the wind."""
    from bench_eiv_marginal import campaign
    from eiv_mean_model import MeanCorrectedModel

    model, truth, pt, p_true, spec, _ = field
    m, _ = campaign(truth, pt, dataclasses.replace(spec, n_records=12), 4001)
    sigma = np.c_[m.condition_sigma["wind_speed"], m.condition_sigma["pitch"]]
    proto = MeanCorrectedModel(model, sigma)
    ev, G = proto.jacobian(p_true, m.conditions)
    assert np.all(ev.ok) and not proto.capabilities.refinable
    scale = np.array([q.scale for q in model.parameters])
    seen = int(np.argmax(np.abs(G[:, :, :-2] * scale[:-2]).max(axis=(0, 1))))      # the field node these records see most
    for j in (seen, len(p_true) - 2, len(p_true) - 1):
        h = 1e-4 * scale[j]
        plus, minus = p_true.copy(), p_true.copy()
        plus[j] += h
        minus[j] -= h
        fd = (proto.evaluate(plus, m.conditions).values - proto.evaluate(minus, m.conditions).values) / (2 * h)
        np.testing.assert_allclose(G[:, :, j], fd, rtol=2e-4, atol=1e-6 * np.abs(fd).max())
    below = m.conditions.wind_speed / spec.anemometer_scale < 9.0            # power ∝ V³ well below rated
    power = [c.name for c in model.channels].index("power")
    assert np.all(ev.values[below, power] > model.evaluate(p_true, m.conditions).values[below, power])
    with pytest.raises(ValueError, match="12 records"):
        proto.evaluate(p_true, m.conditions.subset(slice(0, 5)))
