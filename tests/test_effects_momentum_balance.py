"""``momentum_balance`` (model form): derivatives, no effect at nominal, and its fingerprint: a
stronger balance (m > 1) gives less induction, so more power and thrust where the rotor is
loaded, power more than thrust, and almost nothing where the induction is small."""

from test_effects_chain import check_effect_derivatives, check_nominal_is_no_effect, relative_change, tsr_sweep

from calib.effects import EFFECTS


def test_momentum_balance_jacobian_matches_central_differences():
    check_effect_derivatives("momentum_balance", {}, [1.1])


def test_momentum_balance_at_nominal_is_no_effect():
    check_nominal_is_no_effect("momentum_balance", {})


def test_a_stronger_momentum_balance_adds_power_where_the_rotor_is_loaded():
    d = relative_change("momentum_balance", [1.1], tsr_sweep([9.0, 7.5, 3.0]), channels=("power", "thrust"))
    assert d[0, 0] > d[0, 1] > 0.005             # loaded (λ 9): more power, more thrust; power more
    assert d[1, 0] > 0.005                         # design λ
    assert abs(d[2, 0]) < 0.5 * d[0, 0]           # λ 3: little induction, little change


def test_the_induction_models_parameters_are_model_form_and_the_others_physical():
    kinds = {name: cls.kind for name, cls in EFFECTS.items()}
    assert kinds["momentum_balance"] == kinds["tip_loss"] == "model_form"
    assert {kinds[n] for n in EFFECTS if n not in ("momentum_balance", "tip_loss")} == {"physical"}
