"""calib.powercurve: the calibrated power curve, its uncertainty and the AEP (issue 41).

The result used is a real calibration: ``calib run workflows/wind_tunnel_hub_loads.toml`` (NREL
Phase VI, MAP estimator, hub power and thrust), about 10 s.
"""

import csv
import dataclasses
from pathlib import Path

import numpy as np
import pytest
from scipy.special import erf

from calib.bem.steady_control import steady_power_curve
from calib.cli import main
from calib.errors import InputError
from calib.models.bem_model import BemModel
from calib.powercurve import (FixedSpeed, VariableSpeed, aep, calibrated_power_curve, iec_bins, parse_measurement,
                              posterior_draws, rayleigh_cdf, weibull_cdf)
from calib.powercurve.schedule import schedule_from_table
from calib.rotor.geometry import OperatingSchedule
from calib.rotor.library import load_rotor, reference_path

ROOT = Path(__file__).resolve().parents[1]

#: An operating schedule for the Phase VI rotor (R = 5.03 m) so the variable-speed path runs on a calibrated
#: result: rated 5 kW aerodynamic, 40-72 rpm, design λ 5.
PHASE_VI_SCHEDULE = OperatingSchedule(rated_power=5000.0, min_rotor_speed=40.0, max_rotor_speed=72.0,
                                      design_tsr=5.0, fine_pitch=3.0, cut_in=4.0, cut_out=20.0)


@pytest.fixture(scope="module")
def wind_tunnel_result(tmp_path_factory):
    from calib.calibration.result_files import load_result

    out = tmp_path_factory.mktemp("wt")
    assert main(["run", str(ROOT / "workflows" / "wind_tunnel_hub_loads.toml"), "--out", str(out), "-q"]) == 0
    stage = next(out.glob("stage*/result.json")).parent
    return stage, load_result(stage)


def _variable_speed(model, rule):
    rotor = dataclasses.replace(model.rotor, schedule=PHASE_VI_SCHEDULE)
    return rotor, VariableSpeed.from_rotor(rotor, rule)


def _scaled(result, factor):
    u = result.uncertainty
    return result.replace(uncertainty=dataclasses.replace(u, cov_p=u.cov_p * factor, cov_alias=u.cov_alias * factor))


# ------------------------------------------------------------------------------ (a) delta method vs draws
@pytest.mark.parametrize("kind", ["fixed", "variable"])
def test_delta_method_agrees_with_draws_where_near_linear(wind_tunnel_result, kind):
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    small = _scaled(result, 1e-4)          # σ of every parameter 1 % of the calibration's: near-linear
    schedule = FixedSpeed(72.0, 3.0) if kind == "fixed" else _variable_speed(model, "optimal")[1]
    v = iec_bins(5.0, 15.0, 1.0)
    pc = calibrated_power_curve(small, v, schedule, n_draws=300, seed=3, model=model)
    assert pc.failed_draws == 0
    sd, dd = pc.draw_std("power"), pc.delta_std["power"]
    # region 3's spread is the pitch search's tolerance (1e-4 P_rated), checked below
    spread = (pc.central.region == 2) & (sd > 1e-6 * np.nanmax(pc.central.power))
    assert spread.sum() >= 3
    # 300 draws: the sample σ scatters by 1/sqrt(2·299) = 4.1 %; 13 % is 3.2 of those
    np.testing.assert_allclose(dd[spread], sd[spread], rtol=0.13)
    # the same draws through the linearization: no sampling scatter, so tighter
    D, _ = posterior_draws(result.estimate.p_hat, pc.cov, -np.inf, np.inf, 300, 3)
    lin = (D - result.estimate.p_hat) @ pc.grad_power.T
    np.testing.assert_allclose(np.std(lin, axis=0, ddof=1)[spread], sd[spread], rtol=0.03)
    if kind == "variable":
        assert np.any(pc.central.region == 3) and np.any(pc.central.region == 2)
        # the pitch holds rated power in region 3: no power spread there, by either method
        r3 = pc.central.region == 3
        assert np.all(dd[r3] == 0)
        assert np.all(sd[r3] < 2e-4 * PHASE_VI_SCHEDULE.rated_power)


# ------------------------------------------------------------------------------ (b) zero covariance
def test_zero_covariance_collapses_the_band_onto_steady_power_curve(wind_tunnel_result):
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    nominal_p = model.chain.nominal()
    zero = result.replace(estimate=dataclasses.replace(result.estimate, p_hat=nominal_p),
                          uncertainty=dataclasses.replace(result.uncertainty,
                                                          cov_p=np.zeros_like(result.uncertainty.cov_p),
                                                          cov_alias=np.zeros_like(result.uncertainty.cov_p)))
    rotor, schedule = _variable_speed(model, "design")
    v = iec_bins(4.0, 20.0, 0.5)
    pc = calibrated_power_curve(zero, v, schedule, n_draws=5, model=model)
    r2 = pc.central.region == 2
    for q in ("power", "thrust", "pitch", "rotor_speed"):
        x = pc.draws[q]
        assert np.all(x == x[0]), q                                 # every draw is the same curve
        # the draws are solved batched (one solve over every draw's points), the central curve alone: another
        # summation order in the compiled kernel, so equal to round-off rather than to the bit
        np.testing.assert_allclose(x[0][r2], getattr(pc.central, q)[r2], rtol=1e-12)
    # above rated the draws start their pitch search from the central curve: the same rated power to 1e-4
    np.testing.assert_allclose(pc.draws["power"][0][~r2], pc.central.power[~r2], rtol=1e-4)
    ref = steady_power_curve(rotor, v, settings=model.settings, polars=model.polars)
    assert ref.result.n_failed == 0 and np.all(pc.central.ok)
    np.testing.assert_allclose(pc.central.rotor_speed, ref.rotor_speed, rtol=1e-12)
    assert r2.any() and (~r2).any()
    np.testing.assert_allclose(pc.central.power[r2], ref.result.power[r2], rtol=1e-9)
    # above rated both pitch to rated power: steady_power_curve by bisection to 1e-3 deg, this to 1e-4 P_rated
    np.testing.assert_allclose(pc.central.power[~r2], ref.result.power[~r2], rtol=2e-3)
    np.testing.assert_allclose(pc.central.pitch, ref.pitch, atol=0.02)
    # the delta method collapses too, and the nominal curve is the central one
    assert np.all(pc.delta_std["power"][np.isfinite(pc.delta_std["power"])] == 0)
    np.testing.assert_allclose(pc.nominal.power, pc.central.power, rtol=1e-4)


# ------------------------------------------------------------------------------ (c) AEP against analytic integrals
def _ramp_aep_analytic(a, b, c, P_r, mean):
    """∫ P(V) f(V) dV × 8760 h for P = P_r (V − a)/(b − a) on [a, b], P_r on [b, c], 0 beyond, Rayleigh(mean)."""
    k = np.pi / (4 * mean ** 2)
    E = lambda x: np.exp(-k * x ** 2)  # noqa: E731  (1 − F)
    gauss = 0.5 * np.sqrt(np.pi / k) * (erf(np.sqrt(k) * b) - erf(np.sqrt(k) * a))   # ∫_a^b E dV
    ramp = (-(b - a) * E(b) + gauss) / (b - a)         # ∫_a^b (V − a)/(b − a) f dV by parts
    flat = E(b) - E(c)
    return 8760.0 * P_r * (ramp + flat)


@pytest.mark.parametrize("mean", [4.0, 7.0, 11.0])
def test_aep_of_a_ramp_matches_the_analytic_integral(mean):
    a, b, c, P_r = 3.0, 12.0, 25.0, 5e6
    exact = _ramp_aep_analytic(a, b, c, P_r, mean)
    cdf = lambda x: rayleigh_cdf(x, mean)  # noqa: E731
    for step, rtol in ((0.5, 0.01), (0.05, 2e-4)):
        v = iec_bins(a + step, c, step)                # P_0 = 0 at V_0 = a: the ramp starts at zero
        P = np.clip(P_r * (v - a) / (b - a), 0, P_r)
        assert aep(v, P, cdf) == pytest.approx(exact, rel=rtol)
    # a Weibull of k = 2 and A = 2 V̄/√π is the Rayleigh distribution of mean V̄
    v = iec_bins(3.5, 25, 0.5)
    P = np.clip(P_r * (v - a) / (b - a), 0, P_r)
    assert aep(v, P, lambda x: weibull_cdf(x, 2.0, 2 * mean / np.sqrt(np.pi))) == pytest.approx(aep(v, P, cdf),
                                                                                                 rel=1e-12)


def test_aep_of_a_constant_power_is_hours_times_probability():
    # P = P_r on every bin: the IEC sum telescopes to P_r [F(V_N) − F(V_0)] minus half the first bin's probability
    v = iec_bins(3.0, 25.0, 0.5)
    F = lambda x: rayleigh_cdf(x, 8.0)  # noqa: E731
    expected = 8760 * 2e6 * (F(25.0) - F(2.5) - 0.5 * (F(3.0) - F(2.5)))
    assert aep(v, np.full(v.size, 2e6), F) == pytest.approx(expected, rel=1e-12)


# ------------------------------------------------------------------------------ (d) NREL 5-MW against OpenFAST
def test_nrel5mw_nominal_power_curve_against_openfast_steady_table():
    """The native BEM through the rotor's schedule (not OpenFAST's operating points) against OpenFAST's
    steady table (calib/data/reference/NREL5MW_Oper_openfast_sim.csv, provenance in PROVENANCE.txt there).

    Tolerances per bin, electrical power (aerodynamic × 0.944): 5 m/s 7 % and 6 m/s 4 % (the schedule's
    minimum rotor speed is 6.9 rpm, OpenFAST's controller runs 7.5 and 7.9 rpm there), 7-11 m/s 3.5 %
    (the rigid BEM is 1-3 % above OpenFAST in region 2, tests/test_bem_validation.py), 12-25 m/s 0.1 %
    (rated); blade pitch above rated within 0.4°; aerodynamic thrust (RtAeroFxh) 8 % at 5-7 m/s (there
    OpenFAST's rotor runs 3-15 % faster than the schedule's λ 7.55 or its 6.9 rpm minimum) and 3 % from 8 m/s.
    """
    rotor = load_rotor("nrel5mw")
    model = BemModel(rotor, None, ("power", "thrust"), nuisance=())
    with open(reference_path("NREL5MW_Oper_openfast_sim.csv"), newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if 5.0 <= float(r["WS_[m/s]"]) <= 25.0]
    col = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    v = col("WS_[m/s]")
    schedule = VariableSpeed.from_rotor(rotor, "design")
    curve = schedule.solve(model.solve, np.zeros(0), v, 1.225)
    assert np.all(curve.ok)
    power = curve.power * schedule.generator_efficiency / col("GenPower_[kW]") / 1e3 - 1
    tol = np.where(v <= 5, 0.07, np.where(v <= 6, 0.04, np.where(v <= 11, 0.035, 0.001)))
    assert np.all(np.abs(power) < tol), dict(zip(v, np.round(power, 4)))
    above = v >= 12
    assert np.all(curve.region[above] == 3) and np.all(curve.region[~above] == 2)
    assert np.all(np.abs(curve.pitch[above] - col("BldPitch_[deg]")[above]) < 0.4)
    thrust = curve.thrust / (col("RtAeroFxh_[kN]") * 1e3) - 1
    assert np.all(np.abs(thrust) < np.where(v <= 7, 0.08, 0.03)), dict(zip(v, np.round(thrust, 4)))


# ------------------------------------------------------------------------------ the command, and bad input
def test_powercurve_command_writes_tables_figures_and_report(wind_tunnel_result, tmp_path, capsys):
    stage, _ = wind_tunnel_result
    out = tmp_path / "pc"
    assert main(["powercurve", str(stage), "--schedule", "fixed", "--rotor-speed", "72", "--pitch", "3",
                 "--wind", "5:15:0.5", "--draws", "20", "--out", str(out), "--weibull", "2,7",
                 "--measurement", "anemometer=wind:2", "--measurement", "transducer=power:0.5",
                 "--measurement", "scatter=power:1:A"]) == 0
    printed = capsys.readouterr().out
    assert "Calibrated AEP at Weibull k=2 A=7 m/s" in printed and "P90" in printed
    report = (out / "report.md").read_text()
    assert "| scatter | A | power | 1 % | uncorrelated across bins (quadrature) |" in report
    assert "| anemometer | B | wind | 2 % | correlated across bins (linear) |" in report
    for name in ("powercurve.csv", "powercurve.json", "aep.csv", "aep.json", "powercurve.png", "cp_tsr.png",
                 "aep.png", "report.md"):
        assert (out / name).stat().st_size > 0, name
    import json
    data = json.loads((out / "aep.json").read_text())
    names = [r["distribution"] for r in data["aep"]]
    assert names[:8] == [f"Rayleigh {m} m/s" for m in range(4, 12)] and names[8].startswith("Weibull")
    r = data["aep"][3]
    assert set(r["sigma_mwh"]) >= {"calibration (draws)", "model discrepancy", "anemometer", "transducer"}
    assert r["p90_mwh"] < r["p50_mwh"]
    assert (out / "report.md").read_text().splitlines()[2].startswith("Calibrated AEP")


def test_without_draws_the_delta_method_carries_the_calibration(wind_tunnel_result, tmp_path, capsys):
    stage, _ = wind_tunnel_result
    assert main(["powercurve", str(stage), "--schedule", "fixed", "--rotor-speed", "72", "--pitch", "3",
                 "--wind", "5:15:0.5", "--draws", "0", "--out", str(tmp_path)]) == 0
    assert "by the delta method only: no posterior draws" in capsys.readouterr().out
    import json
    row = json.loads((tmp_path / "aep.json").read_text())["aep"][4]
    assert row["sigma_mwh"]["calibration (draws)"] is None
    assert row["sigma_total_mwh"] >= row["sigma_calibration_delta_mwh"] > 0


def test_schedule_table(tmp_path, wind_tunnel_result):
    _, result = wind_tunnel_result
    path = tmp_path / "sched.csv"
    path.write_text("wind_speed,rotor_speed,pitch\n5,72,3\n15,72,3\n")
    table = schedule_from_table(path)
    model = result.rebuild_model()
    v = iec_bins(5, 15, 1)
    a = table.solve(model.solve, result.estimate.p_hat, v, 1.225)
    b = FixedSpeed(72.0, 3.0).solve(model.solve, result.estimate.p_hat, v, 1.225)
    np.testing.assert_array_equal(a.power, b.power)


@pytest.mark.parametrize("args, names", [
    (["/nonexistent/result"], "RESULT_DIR"),
    (["{stage}", "--wind", "3-25"], "--wind"),
    (["{stage}", "--wind", "10:5:0.5"], "--wind"),
    (["{stage}", "--density", "-1"], "--density"),
    (["{stage}", "--weibull", "0,8"], "--weibull"),
    (["{stage}", "--weibull=-1.5,8"], "--weibull"),
    (["{stage}", "--weibull", "2,0"], "--weibull"),
    (["{stage}", "--weibull=2,-7"], "--weibull"),
    (["{stage}", "--weibull", "2"], "--weibull"),
    (["{stage}", "--measurement", "anemometer=speed:2"], "--measurement"),
    (["{stage}", "--availability", "1.5"], "--availability"),
    (["{stage}"], "--schedule"),                 # the Phase VI rotor has no schedule of its own
    (["{stage}", "--schedule", "fixed"], "--rotor-speed"),
    (["{stage}", "--schedule", "missing.csv"], "missing.csv"),
    (["{stage}", "--measurement", "scatter=power:1:C"], "--measurement"),
    (["{stage}", "--schedule", "fixed", "--rotor-speed", "72", "--pitch", "3", "--histogram", "nohist.csv"],
     "--histogram"),
])
def test_bad_input_is_a_clean_error_naming_the_option(wind_tunnel_result, tmp_path, capsys, args, names):
    stage, _ = wind_tunnel_result
    args = [a.format(stage=stage) for a in args]
    assert main(["powercurve", *args, "--draws", "2", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("calib: error:") and names in err and "Traceback" not in err


def test_measurement_items():
    m = parse_measurement("anemometer calibration=wind:2%")
    assert (m.name, m.kind, m.relative) == ("anemometer calibration", "wind", 0.02)
    v = np.array([5.0, 6.0, 7.0])
    P = np.array([1.0, 2.0, 3.0]) * 1e6          # dP/dV = 1 MW per m/s
    np.testing.assert_allclose(m.power_std(v, P), 0.02 * v * 1e6)
    np.testing.assert_allclose(parse_measurement("rho=density:3").power_std(v, P), 0.01 * v * 1e6)
    np.testing.assert_allclose(parse_measurement("t=power:0.5").power_std(v, P), 0.005 * P)


class _FailingAt:
    """A model whose solve fails at one wind speed for the draws with p[0] above the estimate's."""

    def __init__(self, model, wind_speed, p0):
        self._model, self._v, self._p0 = model, wind_speed, p0

    def __getattr__(self, name):
        return getattr(self._model, name)

    def solve(self, p, conditions, sensitivities=False):
        from calib.types import Status
        res = self._model.solve(p, conditions, sensitivities)
        if p[0] > self._p0:
            hit = np.isclose(conditions.wind_speed, self._v)
            res = dataclasses.replace(res, status=np.where(hit, int(Status.NOT_CONVERGED), res.status),
                                      power=np.where(hit, np.nan, res.power))
        return res


def test_failed_solves_are_counted_never_dropped(wind_tunnel_result):
    from calib.powercurve.command import summary_paragraph
    _, result = wind_tunnel_result
    p_hat = result.estimate.p_hat
    model = _FailingAt(result.rebuild_model(), 10.0, p_hat[0])
    v = iec_bins(5.0, 15.0, 1.0)
    pc = calibrated_power_curve(result, v, FixedSpeed(72.0, 3.0), n_draws=30, seed=1, model=model)
    D, _ = posterior_draws(p_hat, pc.cov, [q.lower for q in model.parameters], [q.upper for q in model.parameters],
                           30, 1)
    n_bad = int(np.count_nonzero(D[:, 0] > p_hat[0]))
    assert 0 < n_bad < 30
    assert pc.failed_per_bin.tolist() == [n_bad if x == 10.0 else 0 for x in v]
    assert pc.failed_draws == n_bad
    assert np.isnan(pc.draws["power"][D[:, 0] > p_hat[0], v.tolist().index(10.0)]).all()
    row = pc.aep_table({"R7": lambda x: rayleigh_cdf(x, 7.0)})[0]
    assert (row["draws_used"], row["draws_left_out"]) == (30 - n_bad, n_bad)
    assert f"{n_bad} of 30 draws had a failed BEM solve" in summary_paragraph(pc, [row])
    # the wrapper has no exact Jacobian of the scheduled power: said, not faked
    assert pc.delta_std == {} and any("no delta-method value" in n for n in pc.notes)


def test_a_schedule_the_rotor_cannot_follow_is_said(wind_tunnel_result):
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    v = iec_bins(5.0, 10.0, 1.0)

    def schedule(**change):
        return VariableSpeed.from_rotor(dataclasses.replace(model.rotor, schedule=dataclasses.replace(
            PHASE_VI_SCHEDULE, **change)), "design")

    # 1 MW from a 10 m rotor: above the Betz limit 16/27·½ρπR²V³ at 10 m/s (28.8 kW, computed here)
    betz = 16 / 27 * 0.5 * 1.225 * np.pi * model.rotor.rotor_radius ** 2 * 10.0 ** 3
    assert 25e3 < betz < 35e3
    with pytest.raises(InputError, match=r"above what the rotor can produce.*Betz limit at the highest bin 10 m/s"):
        calibrated_power_curve(result, v, schedule(rated_power=1e6), n_draws=2, model=model)
    # below Betz but above what this rotor makes (about 10 kW at 10 m/s): every bin in region 2, said
    pc = calibrated_power_curve(result, v, schedule(rated_power=0.9 * betz), n_draws=2, model=model)
    assert any("does not reach rated power" in w for w in pc.warnings)
    assert np.all(pc.central.region == 2)
    # a speed limit below what the design λ asks at cut-in (5·4/5.03 rad/s = 38 rpm): refused
    with pytest.raises(InputError, match=r"speed limit 20 rpm is below the 3\d\.\d+ rpm .* at cut-in"):
        schedule(min_rotor_speed=10.0, max_rotor_speed=20.0)
    # above cut-in's speed but below the first bin's (47 rpm at 5 m/s): runs, and says so
    pc = calibrated_power_curve(result, v, schedule(min_rotor_speed=10.0, max_rotor_speed=45.0), n_draws=2,
                                model=model)
    assert any("maximum speed 45 rpm from the first bin" in w for w in pc.warnings)
    with pytest.raises(Exception, match="cannot be followed"):
        schedule(min_rotor_speed=80.0)


def test_powercurve_help_describes_every_option(capsys):
    with pytest.raises(SystemExit):
        main(["powercurve", "--help"])
    text = capsys.readouterr().out
    for option in ("--wind", "--density", "--draws", "--schedule", "--tsr", "--weibull", "--availability",
                   "--measurement", "--out"):
        assert option in text


# ------------------------------------------------------------------------------ batched draws (issue 41 item 5)
@pytest.mark.parametrize("kind", ["variable", "fixed", "table"])
def test_batched_draws_equal_the_per_draw_loop(wind_tunnel_result, kind, tmp_path):
    """The batched path (every draw's schedule in a few solves with per-point parameters) against the
    straightforward loop solving each draw's schedule with ``model.solve`` at that draw's parameters.
    Bins up to 25 m/s: Phase VI deep in stall, where the multiple-root screen uses the slope table."""
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    if kind == "variable":
        schedule = _variable_speed(model, "optimal")[1]
    elif kind == "fixed":
        schedule = FixedSpeed(72.0, 3.0)
    else:
        path = tmp_path / "table.csv"
        path.write_text("wind_speed,rotor_speed,pitch\n5,60,2\n15,72,4\n25,72,10\n")
        schedule = schedule_from_table(path)
    v = iec_bins(4.0, 25.0, 1.0)
    loop = calibrated_power_curve(result, v, schedule, n_draws=6, seed=5, model=model, batched=False)
    batch = calibrated_power_curve(result, v, schedule, n_draws=6, seed=5, model=model, batched=True)
    assert any("one by one" in n for n in loop.notes) and any("batched" in n for n in batch.notes)
    np.testing.assert_array_equal(batch.draw_status, loop.draw_status)
    assert batch.n_bem_points == loop.n_bem_points
    for q in ("power", "thrust", "cp", "ct", "rotor_speed", "pitch"):
        np.testing.assert_allclose(batch.draws[q], loop.draws[q], rtol=1e-9, atol=1e-9, equal_nan=True)
    np.testing.assert_allclose(batch.tsr_opt, loop.tsr_opt, rtol=1e-12, equal_nan=True)
    if kind == "variable":
        assert np.any(loop.central.region == 3)      # the pitch search ran in both paths


def test_a_wrapped_model_is_solved_per_draw_and_says_so(wind_tunnel_result):
    _, result = wind_tunnel_result
    model = _FailingAt(result.rebuild_model(), 10.0, np.inf)
    pc = calibrated_power_curve(result, iec_bins(5.0, 7.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=2, model=model)
    assert any("solved one by one" in n and "_FailingAt" in n for n in pc.notes)
    with pytest.raises(InputError, match="cannot be batched"):
        calibrated_power_curve(result, iec_bins(5.0, 7.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=2, model=model,
                               batched=True)


def test_weibull_refuses_a_shape_or_scale_not_positive():
    for k, A, what in ((0.0, 8.0, "shape k must be > 0"), (-2.0, 8.0, "shape k"), (2.0, 0.0, "scale A must be > 0"),
                       (2.0, -8.0, "scale A"), (float("nan"), 8.0, "shape k")):
        with pytest.raises(InputError, match=what):
            weibull_cdf(5.0, k, A)


def test_bins_outside_the_calibration_envelope_are_flagged_with_the_reasons(wind_tunnel_result, tmp_path):
    """The calibration saw 72 rpm and λ 2-7.5 (wind 5.1-19 m/s with R = 5.03 m): 3-4.5 m/s (λ > 8.4) and
    20-25 m/s (λ < 1.9) lie outside; the bins say why, and the paragraph and the CSV carry it."""
    from calib.powercurve.command import summary_paragraph, write_outputs, distributions
    _, result = wind_tunnel_result
    v = iec_bins(3.0, 25.0, 0.5)
    pc = calibrated_power_curve(result, v, FixedSpeed(72.0, 3.0), n_draws=4)
    lam = 72 * np.pi / 30 * result.rebuild_model().rotor.rotor_radius / v
    outside = np.array([bool(e) for e in pc.envelope])
    beyond = (lam > 7.5 * 1.05) | (lam < 2.0 * 0.95)
    inside = (lam < 7.5 * 0.95) & (lam > 2.0 * 1.05)
    assert outside[beyond].all() and not outside[inside].any()
    assert all("tip" in e.lower() or "λ" in e or "tsr" in e.lower() for e in np.array(pc.envelope)[beyond])
    text = summary_paragraph(pc, pc.aep_table(distributions()))
    assert f"{int(outside.sum())} bins lie outside the calibration envelope (extrapolation)" in text
    write_outputs(pc, tmp_path, distributions())
    rows = list(csv.DictReader(l for l in (tmp_path / "powercurve.csv").read_text().splitlines()[1:]))
    assert [r["envelope"] != "inside" for r in rows] == outside.tolist()


def test_a_result_without_a_posterior_says_what_is_left_out(wind_tunnel_result):
    _, result = wind_tunnel_result
    settings = {**result.provenance.settings, "estimator": "truncated"}
    unc = result.uncertainty
    cov_frozen = 0.25 * unc.cov_p
    trunc = result.replace(provenance=dataclasses.replace(result.provenance, settings=settings),
                           uncertainty=dataclasses.replace(unc, gain=np.zeros((0, 0)), cov_frozen=cov_frozen,
                                                           curvature={"samples": 0}))
    assert trunc.estimator == "truncated"
    from calib.powercurve.command import distributions, summary_paragraph
    pc = calibrated_power_curve(trunc, iec_bins(6.0, 10.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=4)
    text = summary_paragraph(pc, pc.aep_table(distributions()))
    assert "Estimator 'truncated' has no posterior" in text and "the prior carries 25 % of its variance" in text
    assert "Left out of the calibration's uncertainty: the correction field between and beyond the nodes" in text
    assert "curvature term (not sampled)" in text
    bad = result.replace(uncertainty=dataclasses.replace(unc, cov_p=np.full_like(unc.cov_p, np.nan)))
    with pytest.raises(InputError, match=r"no usable covariance.*non-finite"):
        calibrated_power_curve(bad, iec_bins(6.0, 10.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=4)


def test_a_torque_calibration_carries_its_field_and_discrepancy_to_power_times_the_rotor_speed(wind_tunnel_result):
    """Power is torque × Ω with Ω a condition: a result calibrated on torque (Phase VI) gives the power curve the
    torque's between-node field and discrepancy σ times Ω [rad/s], the same as a power calibration would."""
    from calib.powercurve.terms import prediction_terms as _prediction_terms
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    pc = calibrated_power_curve(result, iec_bins(5.0, 15.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=0, model=model)
    ref_disc, ref_field, _, _ = _prediction_terms(result, model, pc.central, 1.225, [])
    assert np.all(ref_field > 0)
    omega = pc.central.rotor_speed * np.pi / 30.0

    class TorqueResult:
        """The same result, its power channel predicted as torque (power / Ω)."""

        def __getattr__(self, name):
            return getattr(result, name)

        def predict(self, conditions, m):
            pred = result.predict(conditions, m)
            i = list(pred.channels).index("power")
            per = np.ones(len(pred.channels))[None, :].repeat(len(omega), 0)
            per[:, i] = 1.0 / omega
            channels = tuple("torque" if c == "power" else c for c in pred.channels)
            return dataclasses.replace(pred, channels=channels, field_std=pred.field_std * per,
                                       discrepancy_std=pred.discrepancy_std * per)

    notes = []
    disc, fld, _, _ = _prediction_terms(TorqueResult(), model, pc.central, 1.225, notes)
    np.testing.assert_allclose(fld, ref_field, rtol=1e-12)
    np.testing.assert_allclose(disc, ref_disc, rtol=1e-12, atol=1e-9)
    assert "as torque x rotor speed" in notes[-1]


def test_the_field_between_the_nodes_enters_once_and_correlated_across_the_bins(wind_tunnel_result):
    """The draws and the delta method use Cov(p̂) − Cov_alias when the field term is in (as predict_outputs does,
    which replaces the nodal aliasing term by the field's own); the field's covariance across the bins has the
    prediction's field σ² on its diagonal (another code path: predict_outputs) and gives the AEP a σ no larger
    than the per-bin σ added linearly (Cauchy-Schwarz)."""
    from calib.powercurve.command import distributions
    _, result = wind_tunnel_result
    u = result.uncertainty
    assert u.gain.size and np.any(u.cov_alias != 0)
    pc = calibrated_power_curve(result, iec_bins(5.0, 15.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=0)
    np.testing.assert_allclose(pc.cov, u.cov_p - u.cov_alias, rtol=0, atol=1e-15 * np.abs(u.cov_p).max())
    assert pc.field_cov is not None and np.all(pc.field_std > 0)
    np.testing.assert_allclose(np.sqrt(np.diag(pc.field_cov)), pc.field_std, rtol=1e-8)
    corr = pc.field_cov / np.outer(pc.field_std, pc.field_std)
    assert np.all(np.abs(corr) <= 1 + 1e-9) and np.any(corr < 0.999)   # correlated, not perfectly
    from calib.powercurve.aep import aep_weights
    for row in pc.aep_table(distributions()):
        cdf = distributions()[row["distribution"]]
        c = aep_weights(pc.wind_speed, cdf) * pc.generator_efficiency / 1e6
        linear = float(c @ pc.field_std)
        assert row["sigma_mwh"]["field between nodes"] <= linear * (1 + 1e-9)
        split = row["sigma_calibration_split_mwh"]
        assert np.hypot(split["data"], split["prior"]) == pytest.approx(row["sigma_calibration_delta_mwh"], rel=1e-6)
        assert row["empirical_bayes"]["tau"]["amplitude"] == pytest.approx(u.prior_check["amplitude"])


def test_a_measured_histogram_headlines_the_aep(wind_tunnel_result, tmp_path, capsys):
    """A histogram of a Rayleigh 7 m/s distribution in 0.25 m/s bins gives the Rayleigh row's AEP to 0.5 %
    (an independent reference: the closed-form distribution), and headlines the report."""
    stage, _ = wind_tunnel_result
    edges = np.arange(0.0, 30.01, 0.25)
    F = rayleigh_cdf(edges, 7.0)
    hist = tmp_path / "hist.csv"
    hist.write_text("# Rayleigh 7 m/s in hours\nwind_speed [m/s],hours [h]\n"
                    + "".join(f"{0.5 * (a + b):g},{8760 * (fb - fa):.6f}\n"
                              for a, b, fa, fb in zip(edges[:-1], edges[1:], F[:-1], F[1:])))
    out = tmp_path / "pc"
    assert main(["powercurve", str(stage), "--schedule", "fixed", "--rotor-speed", "72", "--pitch", "3",
                 "--wind", "5:15:0.5", "--draws", "0", "--out", str(out), "--histogram", str(hist)]) == 0
    assert "Calibrated AEP at histogram hist.csv" in capsys.readouterr().out
    import json
    rows = {r["distribution"]: r for r in json.loads((out / "aep.json").read_text())["aep"]}
    h = next(r for k, r in rows.items() if k.startswith("histogram"))
    assert h["p50_mwh"] == pytest.approx(rows["Rayleigh 7 m/s"]["p50_mwh"], rel=5e-3)


# ------------------------------------------------------------------------------ sampling (sandwich) σ, issue 41
def test_the_sampling_covariance_is_the_sandwich_of_the_map(wind_tunnel_result):
    """k D K Kᵀ D from the stored gain equals k H⁻¹ F H⁻¹ built here from the model's Jacobian at the estimate,
    the noise σ and the stated prior (H = F + P⁻¹, F = MᵀM): another code path (direct inverses, not the
    prior-whitened SVD). The same matrices give the Laplace covariance (F/k + P⁻¹)⁻¹ = Cov(p̂) − Cov_alias. The
    AEP row's sampling σ is g Cov_s gᵀ with the delta method's gradient, and not in the total."""
    from calib.powercurve.aep import aep_weights
    from calib.powercurve.sampling import sampling_covariance
    from calib.types import OperatingConditions
    _, result = wind_tunnel_result
    u, est = result.uncertainty, result.estimate
    model = result.rebuild_model()
    names = [c.name for c in model.channels]
    idx = [names.index(c) for c in result.channels]
    _, G = model.jacobian(est.p_hat, OperatingConditions(**result.conditions))
    ok = result.fit.status_after == 0
    M = (G[:, idx, :][ok] / result.fit.sigma[ok][:, :, None]).reshape(-1, G.shape[2]) * est.scale
    sd = u.prior_std / est.scale
    C = model.correction_field().node_correlation(float(result.provenance.settings["prior_correlation"]))
    Pinv = np.linalg.inv(sd[:, None] * C * sd[None, :])
    F, D = M.T @ M, np.outer(est.scale, est.scale)
    Hi = np.linalg.inv(F + Pinv)
    S = sampling_covariance(result)
    np.testing.assert_allclose(S, u.fit_scale * (Hi @ F @ Hi) * D, rtol=0, atol=1e-9 * np.abs(S).max())
    lap = u.cov_p - u.cov_alias
    np.testing.assert_allclose(lap, np.linalg.inv(F / u.fit_scale + Pinv) * D, rtol=0, atol=1e-9 * np.abs(lap).max())
    pc = calibrated_power_curve(result, iec_bins(5.0, 15.0, 1.0), FixedSpeed(72.0, 3.0), n_draws=0)
    row = pc.aep_table({"Rayleigh 7": lambda x: rayleigh_cdf(x, 7.0)})[0]
    g = aep_weights(pc.wind_speed, lambda x: rayleigh_cdf(x, 7.0)) * pc.generator_efficiency / 1e6 @ pc.grad_power
    assert row["sigma_calibration_sampling_mwh"] == pytest.approx(np.sqrt(g @ S @ g), rel=1e-9)
    assert 0 < row["sigma_calibration_sampling_mwh"] < row["sigma_total_mwh"]
    # a truncated result records no gain: no sampling σ, said as NaN
    bare = result.replace(uncertainty=dataclasses.replace(u, gain=np.zeros((0, 0))))
    assert sampling_covariance(bare) is None


def test_interval_coverage_against_monte_carlo():
    """Φ((h − b)/s) − Φ((−h − b)/s) against the share of 200 000 normal errors inside ±h."""
    from calib.powercurve.sampling import interval_coverage
    rng = np.random.default_rng(7)
    for h, b, s in ((1.645, 0.0, 1.0), (2.0, 0.7, 1.3), (0.5, -1.0, 0.4)):
        e = b + s * rng.standard_normal(200_000)
        assert interval_coverage(h, b, s) == pytest.approx(np.mean(np.abs(e) <= h), abs=4e-3)
    assert interval_coverage(1.6448536269514722, 0.0, 1.0) == pytest.approx(0.9, abs=1e-9)


def test_reforming_the_laplace_covariance_with_the_recorded_fit_scale_is_the_recorded_one(wind_tunnel_result):
    """calib.calibration.discrepancy_scale re-forms a real MAP result's Cov(p̂) from its recorded directions:
    with the recorded k it is the recorded covariance to round-off, with k = 1 it is no wider."""
    from calib.calibration.discrepancy_scale import reformed_laplace_covariance
    _, result = wind_tunnel_result
    cov = np.asarray(result.uncertainty.cov_p, float)
    k = float(result.uncertainty.fit_scale)
    np.testing.assert_allclose(reformed_laplace_covariance(result, k), cov, rtol=1e-8, atol=1e-12 * np.abs(cov).max())
    assert np.all(np.linalg.eigvalsh(cov - reformed_laplace_covariance(result, 1.0)) > -1e-10 * np.abs(cov).max())


def test_the_delta_method_is_the_derivative_of_the_schedule_it_linearizes(wind_tunnel_result):
    """The scheduled power's gradient (calib.powercurve.linearized.delta_method) against central differences of
    the variable-speed schedule itself (λ* re-found as VariableSpeed.optimal_tsr finds it: the vertex of a
    parabola through three grid points), along the direction that moves the power most per σ, ±0.05 σ. On
    CCBlade replicate 56003 of bench_powercurve the earlier chain term, −(∂²C_P/∂λ∂p)/(∂²C_P/∂λ²) at λ* from
    ±0.05 in λ, made the delta σ 6.2 × the draws' (the calibrated C_P(λ) has kinks at the correction nodes)."""
    _, result = wind_tunnel_result
    model = result.rebuild_model()
    _, schedule = _variable_speed(model, "optimal")
    v = iec_bins(5.0, 15.0, 1.0)
    pc = calibrated_power_curve(result, v, schedule, n_draws=0, model=model)
    r2 = pc.central.region == 2
    g = np.nan_to_num(pc.grad_power)[r2].sum(axis=0)
    e = 0.05 * pc.cov @ g / np.sqrt(g @ pc.cov @ g)
    up = schedule.solve(model.solve, result.estimate.p_hat + e, v, pc.air_density)
    down = schedule.solve(model.solve, result.estimate.p_hat - e, v, pc.air_density)
    assert up.tsr_opt != down.tsr_opt                      # the step moves λ*: the chain term is exercised
    fd = (up.power - down.power)[r2] / 2
    lin = np.nan_to_num(pc.grad_power)[r2] @ e
    np.testing.assert_allclose(fd, lin, rtol=0.02, atol=0.02 * np.abs(lin).max())


def test_the_optimal_tsr_gradient_is_the_derivative_of_the_schedules_vertex(wind_tunnel_result):
    """dλ*/dp (calib.powercurve.linearized._vertex_gradient) against central differences of
    VariableSpeed.optimal_tsr itself, ±0.05 σ along the direction that moves λ* most per σ. (On this calibration the
    earlier formula, −(∂²C_P/∂λ∂p)/(∂²C_P/∂λ²) at λ* from ±0.05 in λ, is 11 % off the schedule's own derivative.)"""
    from calib.powercurve.linearized import _vertex_gradient

    _, result = wind_tunnel_result
    model = result.rebuild_model()
    _, schedule = _variable_speed(model, "optimal")
    p = result.estimate.p_hat
    cov = result.uncertainty.cov_p
    i_power = [c.name for c in model.channels].index("power")
    g = _vertex_gradient(model, p, schedule, 1.225, i_power)
    assert np.any(g)
    e = 0.05 * cov @ g / np.sqrt(g @ cov @ g)
    up, _ = schedule.optimal_tsr(model.solve, p + e, 1.225)
    down, _ = schedule.optimal_tsr(model.solve, p - e, 1.225)
    assert (up - down) / 2 == pytest.approx(g @ e, rel=0.01)
