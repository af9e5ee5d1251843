"""The effect chain of the native BEM: the refactor's regression, independent paths, layout, specs.

The correction field and the nuisance parameters used to be arguments of ``solve_bem``;
they are now effects of a chain. ``test_nominal_chain_reproduces_pre_refactor_outputs``
compares with values computed by the previous solver (commit d015b57, before the chain) on
the same case; the other tests check the chain against independent paths (a pitch offset is
the measured pitch shifted, a wind-speed scale the measured speed scaled, a zero field no
field) and its layout, registry, specs and finite-difference derivatives of stages the
library does not exercise (a loads-stage effect).
"""

import numpy as np
import pytest

from calib.bem import BemSettings, EffectChain, solve_bem
from calib.corrections import CorrectionGrid
from calib.effects import EFFECTS, Effect, effect_from_spec, make_effect
from calib.errors import InputError
from calib.models.base import OperatingConditions
from calib.types import nominal_vector
from calib.models.bem_model import BemModel
from calib.models.registry import build_model
from calib.types import Parameter
from floats import assert_same_numbers
from synthetic import synthetic_rotor

# ---- computed with the solver before the chain (d015b57), see the module docstring
BASELINE_P = [0.0017096383626592085, 0.06798737701549809, 0.061236053929296624, -0.025515353839383376,
              -0.014898475555322355, -0.026369209651671263, 0.0011394527151439202, 0.00011212887809123519,
              0.0014937712325130879, 0.003694649597948219, 0.003133097549399041, 0.0001928643203112411, 0.4, 1.03]

BASELINE_VALUES = [[111720.73520079583, 27003.854376534353, 226962.90199386497, 0.7721955796339988, 560.5625375856641],
                   [318363.200090991, 50759.572982352416, 433585.740542167, 0.8655117976251158, 1074.4493606951182],
                   [808993.9308213982, 60492.50945706476, 487692.1019525041, 0.7012982068667487, 981.2173559141864]]

BASELINE_JAC = [[[292.10824013759077, 729.5180087786457, 68970.09474453659, 83110.54382224694, 6986.896405162614,
                  3885.2934038589774, -3620.5011840807892, -10547.799001435758, -547215.7374419286, -939231.2351753983,
                  -37469.69171006415, -37056.69428734043, -14284.359685467049, 305048.67478113394],
                 [77.43102703982552, 203.36115034280806, 15192.237605432838, 19535.677046189907, 1387.6505756944366,
                  830.9950250772689, 8.089233848354237, 17.93184902702632, 2701.0260098348763, 2191.0413477248176,
                  384.7713288918302, 109.22713046753559, -3785.581808984116, 37952.537154245336],
                 [736.1984876224894, 2138.2311748352045, 112146.06771152656, 194150.00184955564, 7626.6441406393305,
                  7757.557874510172, 74.28875541812191, 184.37746943569232, 16921.415470273223, 20924.686746154668,
                  1564.861109046303, 970.4817946950409, -33524.312291947484, 309637.59556251904],
                 [0.0, 0.0, 0.693132687665112, 0.015282791771481107, 0.1236496059311748, 0.0020772256021023383, 0.0, 0.0,
                  0.09408378415885549, 0.0019795820810351995, 0.018395077180575613, 0.00029216296926833833,
                  -0.07583958654349215, 1.284140846959819],
                 [1.6060168431616515, 10.234086053764157, 111.9138500254953, 713.1531506943807, 3.0349438809020937,
                  19.33969558149316, 0.11940700930406144, 0.7609021124801374, 9.8585504656563, 62.82203966944824,
                  0.2936532240116283, 1.8712583104570812, -90.2102784352955, 679.8261748966604]],
                [[0.0, 0.0, 116435.75751606082, 151536.80606182085, 64369.743442966916, 44687.41649581721, 0.0, 0.0,
                  -672345.4976787239, -1247937.077734238, -275082.4463207231, -334559.8861300336, -9850.852407889057,
                  495585.69887421024],
                 [0.0, 0.0, 16675.108185739144, 23347.74489007832, 8678.522314134205, 6620.175331056579, 0.0, 0.0,
                  3235.8657711896194, 3187.285409422614, 2398.8804680916137, 980.2466052598742, -3267.2037982675265,
                  34871.60536165266],
                 [0.0, 0.0, 127902.895840815, 233236.03820072795, 52750.26096819485, 63161.12618747474, 0.0, 0.0,
                  22214.41347006762, 30743.628034537393, 11370.604861623238, 8943.937997509547, -33673.72573643138,
                  354987.726227973],
                 [0.0, 0.0, 0.46554031769677084, 0.011256680203967154, 0.5098119685694275, 0.009166480789920016, 0.0, 0.0,
                  0.0877996155451072, 0.0020205682973524347, 0.09892629187520996, 0.0016572066651740379,
                  0.06283847176127294, -1.3050939767974874],
                 [0.0, 0.0, 137.91230212126334, 878.8241379854985, 29.603029152695406, 188.64057938792104, 0.0, 0.0,
                  15.091077367164704, 96.16548237161354, 3.325632130971254, 21.192060068636003, -114.6409520634777,
                  1074.9185709980643]],
                [[1054.6630691862842, 6611.249651794787, 340944.72653667233, 556161.4571062658, 204145.81568593945,
                  71195.67845053865, -5058.548486318668, -31772.59101822815, -1076802.2440121323, -2195695.7912420947,
                  -405896.02029490506, -218506.75902170347, -59114.40495539943, 1799956.7956823239],
                 [74.48735271185234, 467.01751747586314, 22452.815861332114, 36934.30588046883, 13037.508193230038,
                  4597.647687788108, 18.376393604130087, 115.03463152027061, 7972.222685430242, 10827.753923331838,
                  7294.343783605669, 1638.2812252117474, -5252.509353660167, 91511.73290581396],
                 [848.2207584082407, 5326.64504290991, 184391.96727994777, 371986.9772238439, 69280.9821954945,
                  37576.77680393699, 209.2040059730877, 1311.892970440342, 61889.67153842813, 106831.19979710685,
                  33080.94336991464, 12903.85421387267, -53512.55697661242, 870593.961173399],
                 [0.0, 0.0, 0.17787641822824565, 0.0060531605834080755, 0.6931323149803797, 0.013971563333478626, 0.0, 0.0,
                  0.04210827703306942, 0.0013616554771989939, 0.19971731132618506, 0.00344678068804206,
                  0.02360170769479036, -0.4992579711060863],
                 [7.0833497200298945, 45.13751576912674, 222.95761503702477, 1420.7618234806175, 4.640671382265122,
                  29.57193785081715, 1.7426973549246325, 11.10506080425379, 57.73055784447223, 367.8787675408396,
                  1.2490565252045487, 7.9594133893353805, -180.65190410650592, 2575.321688046609]]]


def _baseline_case():
    rotor = synthetic_rotor(n_stations=12, precone_deg=2.5, tilt_deg=5.0, precurve_tip=-1.0)
    grid = CorrectionGrid([-7.3, 4.9, 17.9], [0.37, 1.0])
    channels = ("power", "thrust", "root_flap_moment", "cn@0.35", "fn@0.95")
    model = BemModel(rotor, grid, channels, BemSettings(shear_exponent=0.2))
    cond = OperatingConditions([5.5, 8.0, 16.0], [12.0, 14.0, 16.0], [0.5, 0.0, 9.0], 1.225, [10.0, 0.0, -10.0])
    return model, cond


def fd_check(model, p, cond, which=None, step_rel=1e-4, tol=2e-5):
    """Central differences of ``model.evaluate`` against ``model.jacobian`` for parameters ``which``.

    Errors are relative to the channel's largest |derivative| over the points (with a floor of
    1e-5 of the channel's largest scaled sensitivity, so round-off-level derivatives are not
    compared with themselves). Returns the worst error.
    """
    ev, G = model.jacobian(p, cond)
    assert ev.n_failed == 0, ev.failure_summary()
    params = model.parameters
    which = range(len(params)) if which is None else which
    scales = np.array([max(q.scale, 1e-3) for q in params])
    floor = 1e-5 * np.abs(G * scales).max(axis=(0, 2))
    worst = 0.0
    for j in which:
        par = params[j]
        h = step_rel * max(par.scale, 1e-3)
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (model.evaluate(pp, cond).values - model.evaluate(pm, cond).values) / (2 * h)
        scale = np.maximum(np.maximum(np.abs(fd).max(axis=0), np.abs(G[:, :, j]).max(axis=0)),
                           floor / max(par.scale, 1e-3))
        ok = scale > 0
        err = np.abs(fd - G[:, :, j])[:, ok] / scale[ok]
        worst = max(worst, float(err.max()) if err.size else 0.0)
        assert err.size == 0 or err.max() < tol, (par.name, err.max(axis=0))
    return worst


# ---- shared by the per-effect test files (tests/test_effects_<name>.py) --------------------------
def nrel5mw():
    from calib.rotor.library import load_rotor
    return load_rotor("nrel5mw")


FD_GRID = CorrectionGrid([-7.3, 4.9, 11.3, 17.9], [0.21, 0.63, 1.0])
FD_CHANNELS = ("power", "thrust", "root_flap_moment", "root_edge_moment", "fn@0.95", "ft@0.95", "cn@0.3", "ct@0.6")
# NREL 5-MW (tilted: four sectors): below rated at several λ, a stalled low-λ point (tip near stall), above
# rated pitched; yaw at three points
FD_POINTS = OperatingConditions([5.0, 8.0, 11.0, 12.0, 16.0, 22.0], [7.5, 9.5, 12.1, 6.0, 12.1, 12.1],
                                [0.0, 0.0, 0.0, 0.0, 12.0, 19.0], 1.225, [0.0, 10.0, -5.0, 0.0, 8.0, 0.0])
NUISANCE_EFFECT = {"pitch_offset": "pitch_offset", "wind_scale": "wind_speed_scale"}


def check_effect_derivatives(name, options, values, all_parameters=False):
    """FD check of an effect's Jacobian columns in a NREL 5-MW model with a correction field and the
    nuisance parameters (those the effect is not), all at non-nominal values."""
    nuisance = tuple(n for n, e in NUISANCE_EFFECT.items() if e != name)
    model = BemModel(nrel5mw(), FD_GRID, FD_CHANNELS, BemSettings(), nuisance,
                     effects=[make_effect(name, **options)])
    p = nominal_vector(model.parameters)
    p[:FD_GRID.n_lift] = 0.02                          # a non-zero field under the effect
    for j, q in enumerate(model.parameters):
        p[j] = {"pitch_offset": 0.3, "wind_scale": 1.02}.get(q.name, p[j])
    n_eff = len(values)
    p[-n_eff:] = values
    which = list(range(len(p) - n_eff - 1, len(p)))   # the effect's parameters and the nuisance next to them
    if all_parameters:
        g = FD_GRID
        which = [0, g.n_lift - 1, g.n_lift + 5, g.n_params - 1] + list(range(g.n_params, len(p)))
    return fd_check(model, p, FD_POINTS, which=which)


def check_nominal_is_no_effect(name, options):
    """The effect at its nominal parameters gives the outputs of the model without it (to a few
    ulps: the chain may sum in another order)."""
    model = BemModel(nrel5mw(), None, FD_CHANNELS, BemSettings(), ("pitch_offset", "wind_scale"),
                     effects=[make_effect(name, **options)])
    bare = BemModel(nrel5mw(), None, FD_CHANNELS, BemSettings(), ("pitch_offset", "wind_scale"))
    p = nominal_vector(model.parameters)
    p[:2] = [0.3, 1.02]
    ev, ref = model.evaluate(p, FD_POINTS), bare.evaluate(p[:2], FD_POINTS)
    assert ev.n_failed == 0
    assert_same_numbers(ev.values, ref.values)


FP_SETTINGS = BemSettings(use_tilt=False)
FP_RPM = 12.1
FP_LAMBDA = np.array([3.0, 4.0, 5.0, 6.0, 7.0, 7.5, 8.0, 9.0, 10.0, 11.0, 12.0])


def tsr_sweep(lam=FP_LAMBDA, pitch=0.0):
    """NREL 5-MW at rated rotor speed over tip-speed ratios ``lam`` (wind speed from λ)."""
    return OperatingConditions(FP_RPM * np.pi / 30 * nrel5mw().rotor_radius / np.asarray(lam), FP_RPM, pitch)


def relative_change(name, values, cond, channels=("power",), **options):
    """Outputs with the effect at ``values`` over the nominal model's, minus 1 (n_points, n_channels)."""
    model = BemModel(nrel5mw(), None, channels, FP_SETTINGS, (), effects=[make_effect(name, **options)])
    base = BemModel(nrel5mw(), None, channels, FP_SETTINGS, ())
    ev, ev0 = model.evaluate(np.asarray(values, float), cond), base.evaluate([], cond)
    assert ev.n_failed == 0 and ev0.n_failed == 0
    return ev.values / ev0.values - 1.0


# ---- the chain ------------------------------------------------------------------------------------
def test_nominal_chain_reproduces_pre_refactor_outputs():
    model, cond = _baseline_case()
    assert [q.name for q in model.parameters][-2:] == ["pitch_offset", "wind_scale"]
    ev, G = model.jacobian(np.array(BASELINE_P), cond)
    assert ev.n_failed == 0
    assert_same_numbers(ev.values, np.array(BASELINE_VALUES))     # a few ulps: summation orders differ by CPU
    ref = np.array(BASELINE_JAC)
    scale = np.abs(ref).max(axis=(0, 2), keepdims=True)
    assert np.abs(G - ref).max() <= 1e-13 * scale.max()
    assert (np.abs(G - ref) / scale).max() < 1e-13                              # round-off of reordered sums


def test_pitch_offset_effect_is_the_measured_pitch_shifted():
    model, cond = _baseline_case()
    p = np.array(BASELINE_P)
    p[-2], p[-1] = 0.7, 1.0
    shifted = OperatingConditions(cond.wind_speed, cond.rotor_speed, cond.pitch + 0.7, cond.air_density, cond.yaw)
    q = p.copy()
    q[-2] = 0.0
    assert_same_numbers(model.evaluate(p, cond).values, model.evaluate(q, shifted).values)


def test_wind_speed_scale_effect_is_the_measured_speed_scaled():
    model, cond = _baseline_case()
    p = np.array(BASELINE_P)
    p[-2], p[-1] = 0.0, 1.07
    scaled = OperatingConditions(cond.wind_speed * 1.07, cond.rotor_speed, cond.pitch, cond.air_density, cond.yaw)
    q = p.copy()
    q[-1] = 1.0
    assert_same_numbers(model.evaluate(p, cond).values, model.evaluate(q, scaled).values)
    # coefficients stay referred to the measured wind speed
    a, b = model.solve(p, cond), model.solve(q, scaled)
    np.testing.assert_allclose(a.cp, b.cp * 1.07 ** 3, rtol=1e-14)
    np.testing.assert_allclose(a.inflow_wind_speed, cond.wind_speed * 1.07, rtol=0)


def test_zero_correction_field_is_no_field():
    model, cond = _baseline_case()
    bare = BemModel(model.rotor, None, [c.name for c in model.channels], model.settings)
    p = nominal_vector(model.parameters)
    p[-2], p[-1] = 0.3, 0.97
    assert_same_numbers(model.evaluate(p, cond).values, bare.evaluate(p[-2:], cond).values)


def test_solve_bem_takes_the_chain_and_defaults_to_nominal_values():
    rotor = synthetic_rotor()
    cond = OperatingConditions([8.0, 11.0], [15.0, 15.0], [0.0, 2.0])
    chain = EffectChain([make_effect("pitch_offset"), make_effect("wind_speed_scale")])
    plain = solve_bem(rotor, cond)
    nominal = solve_bem(rotor, cond, effects=chain)
    assert_same_numbers(plain.power, nominal.power)
    moved = solve_bem(rotor, cond, effects=chain, p=[1.0, 1.0])
    assert np.all(moved.power != plain.power)
    np.testing.assert_array_equal(moved.inflow_pitch, cond.pitch + 1.0)
    with pytest.raises(InputError, match="expected 2 parameter values"):
        solve_bem(rotor, cond, effects=chain, p=[1.0])
    with pytest.raises(InputError, match="'wind_scale' is not finite"):
        solve_bem(rotor, cond, effects=chain, p=[0.0, np.nan])


class LoadGain(Effect):
    """A test-only loads-stage effect: N' → (1 + g) N', T' → (1 + g η) T'."""

    name = "test_load_gain"
    stage = "loads"
    PARAMETERS = (Parameter("load_gain", 0.0, -0.5, 0.5, 0.05, "-", "effect"),)

    def apply(self, theta, loads, ctx):
        (g,) = theta
        return loads.replace(Np=loads.Np * (1.0 + g), Tp=loads.Tp * (1.0 + g * ctx.eta))


def test_parameter_order_corrections_then_nuisance_then_effects():
    rotor = synthetic_rotor()
    grid = CorrectionGrid([0.0, 10.0], [0.5, 1.0])
    model = BemModel(rotor, grid, ("power",), nuisance=("wind_scale",), effects=[LoadGain(), "pitch_offset"])
    names = [q.name for q in model.parameters]
    assert names[:grid.n_params] == [q.name for q in grid.parameters()]
    assert names[grid.n_lift - 1].startswith("dCL") and names[grid.n_lift].startswith("dCD")
    assert names[grid.n_params:] == ["wind_scale", "load_gain", "pitch_offset"]
    assert [e.name for e in model.chain.effects] == ["correction_field", "wind_speed_scale", "test_load_gain",
                                                     "pitch_offset"]


def test_loads_stage_effect_derivatives_match_central_differences():
    rotor = synthetic_rotor(n_stations=12, tilt_deg=5.0)
    grid = CorrectionGrid([-7.3, 4.9, 17.9], [0.37, 1.0])
    model = BemModel(rotor, grid, ("power", "thrust", "root_edge_moment", "ft@0.8", "cn@0.5"),
                     BemSettings(n_sectors=2), effects=[LoadGain()])
    p = nominal_vector(model.parameters)
    p[-1], p[-3] = 0.2, 0.5
    cond = OperatingConditions([6.0, 9.0, 14.0], [12.0, 14.0, 16.0], [0.0, 1.0, 6.0])
    fd_check(model, p, cond)
    ev0, G = model.jacobian(p, cond)
    # analytic: thrust ∝ (1 + g), the chord-axis cn does not see a loads-stage effect
    names = [c.name for c in model.channels]
    np.testing.assert_allclose(G[:, names.index("thrust"), -1] * 1.2, ev0.channel("thrust"), rtol=1e-12)
    assert np.all(G[:, names.index("cn@0.5"), -1] == 0.0)


def test_chain_refuses_duplicates_and_bad_stages():
    with pytest.raises(InputError, match="'pitch_offset' appear twice"):
        EffectChain([make_effect("pitch_offset"), make_effect("pitch_offset")])
    rotor = synthetic_rotor()
    with pytest.raises(InputError, match="appear twice"):
        BemModel(rotor, None, ("power",), nuisance=("pitch_offset",), effects=["pitch_offset"])

    class Nowhere(LoadGain):
        name, stage = "nowhere", "wake"
    with pytest.raises(InputError, match="valid stages: conditions, polar, induction, loads"):
        EffectChain([Nowhere()])


def test_registry_names_and_errors_list_the_valid_names():
    assert {"correction_field", "pitch_offset", "wind_speed_scale"} <= set(EFFECTS)
    with pytest.raises(InputError) as err:
        make_effect("pitch_ofset")
    assert "unknown effect 'pitch_ofset'" in str(err.value) and "pitch_offset, wind_speed_scale" in str(err.value)
    with pytest.raises(InputError, match="unknown option.*'offset'.*valid: nominal"):
        make_effect("pitch_offset", offset=1.0)
    with pytest.raises(InputError, match="no parameter 'scale'.*its parameters: wind_scale"):
        make_effect("wind_speed_scale", nominal={"scale": 1.0})
    with pytest.raises(InputError, match="needs its nodes"):
        make_effect("correction_field")
    field = make_effect("correction_field", alpha_nodes_deg=[0, 10], eta_nodes=[0.5, 1.0], cd_scale=0.02)
    assert [q.scale for q in field.parameters()] == [0.1] * 4 + [0.02] * 4
    with pytest.raises(InputError, match="outside its bounds"):
        make_effect("pitch_offset", nominal={"pitch_offset": 50.0})
    e = make_effect("pitch_offset", nominal={"pitch_offset": 1.5})
    assert e.parameters()[0].nominal == 1.5
    assert effect_from_spec(e.spec()).parameters() == e.parameters()


def test_every_registered_effect_declares_itself():
    from calib.bem.stages import STAGES
    from calib.effects import describe_effects
    described = {d["name"]: d for d in describe_effects()}
    assert set(described) == set(EFFECTS)
    for name, cls in EFFECTS.items():
        e = cls(alpha_nodes_deg=[0.0, 10.0], eta_nodes=[0.5, 1.0]) if name == "correction_field" else cls()
        assert e.name == name and e.stage in STAGES and e.fingerprint
        assert cls.__doc__ and "Notes" in cls.__doc__, name          # formula in the docstring
        for q in e.parameters():
            assert str(q.kind) in ("effect", "nuisance", "lift_correction", "drag_correction"), (name, q.name)
            assert q.lower <= q.nominal <= q.upper and q.scale > 0 and q.unit
            if name != "correction_field":
                assert np.isfinite(q.prior_std), (name, q.name)
        # the spec rebuilds the same effect
        again = effect_from_spec(e.spec())
        assert type(again) is cls and again.spec() == e.spec()
        if name != "correction_field":
            assert [q["name"] for q in described[name]["parameters"]] == [q.name for q in e.parameters()]
            assert described[name]["stage"] == e.stage and described[name]["fingerprint"] == e.fingerprint


def test_spec_round_trip_keeps_the_effect_chain():
    from calib.rotor.library import load_rotor
    rotor = load_rotor("nrel5mw")
    grid = CorrectionGrid([0.0, 10.0], [0.5, 1.0])
    effects = [{"name": "wind_speed_scale", "options": {"nominal": {"wind_scale": 1.05}}}]
    model = BemModel(rotor, grid, ("power", "fn@0.95"), BemSettings(use_tilt=False), ("pitch_offset",),
                     effects=effects)
    spec = model.spec()
    assert spec["effects"] == [{"name": "wind_speed_scale", "options": {"nominal": {"wind_scale": 1.05}}}]
    assert model.parameters[-1].nominal == 1.05
    import json
    again = build_model(json.loads(json.dumps(spec)))
    assert [q for q in again.parameters] == [q for q in model.parameters]
    cond = OperatingConditions([7.0, 12.0], [9.0, 12.1], [0.0, 4.0])
    p = nominal_vector(model.parameters)
    p[-2] = 0.8
    np.testing.assert_array_equal(again.evaluate(p, cond).values, model.evaluate(p, cond).values)
    assert not np.array_equal(model.evaluate(p, cond).values, BemModel(
        rotor, grid, ("power", "fn@0.95"), BemSettings(use_tilt=False), ("pitch_offset",)).evaluate(p[:-1], cond).values)
    # a spec written before effects existed still loads
    old = dict(spec)
    del old["effects"]
    assert len(build_model(old).parameters) == grid.n_params + 1
    with pytest.raises(InputError, match="unknown effect 'stall'"):
        build_model({**spec, "effects": [{"name": "stall"}]})
