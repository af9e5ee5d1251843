"""The diagnosis on data with hidden effects (seeds 9000+, used nowhere else).

The default suite runs the control (no effect -> ``none``), the two confusable pairs (named
``ambiguous`` when the data cannot separate them, the right one when they can) and the CLI;
``make demo``'s test covers a hidden rotational augmentation in a form the library does not
fit first. The per-effect hidden-effect tests and the two-effect truth take several minutes
and carry the ``statistics`` marker (``pytest -m statistics``).
"""

import json

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.calibration import CalibrationSettings
from calib.cli import main as cli_main
from calib.corrections import CorrectionGrid
from calib.diagnosis.core import diagnose
from calib.diagnosis.settings import DiagnosisSettings
from calib.effects import make_effect
from calib.errors import InputError
from calib.measurements import synthesize
from calib.models.base import Capabilities
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions

CHANNELS = ("power", "thrust", "root_flap_moment", "fn@0.95")
SETTINGS = BemSettings(use_tilt=False)
GRID = CorrectionGrid([-4.0, 2.0, 8.0, 14.0, 20.0], [0.3, 0.6, 0.85, 1.0])

#: truth parameter values of each hidden effect (clearly visible at 1 % noise)
TRUTH = {"rotational_augmentation": {"stall_delay_strength": 1.0},
         "leading_edge_erosion": {"erosion_drag_rise": 0.008, "erosion_lift_loss": 0.1},
         "pitch_offset": {"pitch_offset": 1.0},
         "reynolds_number": {"reynolds_drag_exponent": 0.5, "reynolds_lift_loss": 0.3},
         "tip_loss": {"tip_loss_strength": 1.0},
         "wind_tunnel_blockage": {"blockage_area_ratio": 0.2},
         "wind_speed_scale": {"wind_scale": 1.04},
         "lift_offset": {"lift_offset": -0.08},
         "momentum_balance": {"momentum_factor": 1.15}}
#: the effects that are the BEM's own approximation: named as model form, never as a physical effect
MODEL_FORM = ("momentum_balance", "tip_loss")


def campaign(rotor, tsr=np.linspace(3.0, 11.0, 9), pitch=(-1.0, 2.0, 5.0, 8.0), rpm=10.0):
    T, P = np.meshgrid(tsr, pitch, indexing="ij")
    v = rpm * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, rpm), P.ravel())


def hidden(effects: dict, cond, seed, channels=CHANNELS, rotor=None, options=None):
    rotor = rotor or load_rotor("nrel5mw")
    fx = [make_effect(n, nominal=v, **(options or {}).get(n, {})) for n, v in effects.items()]
    truth = BemModel(rotor, None, channels, SETTINGS, (), effects=fx)
    p = np.array([q.nominal for q in truth.parameters])
    return synthesize(truth, p, cond, relative_sigma={c: 0.01 for c in channels}, seed=seed)


def run(meas, **diag):
    return diagnose(load_rotor("nrel5mw"), meas, GRID, SETTINGS, CalibrationSettings(cd_min=0.003),
                    DiagnosisSettings(**diag))


def test_control_without_effect_names_none():
    rotor = load_rotor("nrel5mw")
    d = run(hidden({}, campaign(rotor), 9001), recalibrate=False)
    assert d.effect == "none" and d.effects == []
    assert d.before["chi2_per_dof"] < 1.5
    assert all(not c.significant for c in d.candidates)


@pytest.mark.parametrize("wide", [False, True])
def test_blockage_and_wind_scale_ambiguous_unless_the_data_separate_them(wide):
    """Blockage slows the wind by ε(C_T); a wind-speed scale by a constant. A region-2
    campaign at one tip-speed ratio and fine pitch has one C_T, so ε is a constant and the two
    cannot be told apart (ambiguous); a λ × pitch campaign separates them (blockage named)."""
    rotor = load_rotor("nrel5mw")
    if wide:
        cond = campaign(rotor, tsr=np.linspace(3.0, 11.0, 9), pitch=(-1.0, 3.0, 7.0, 11.0))
    else:
        v = np.linspace(5.0, 10.0, 11)
        cond = OperatingConditions(v, 7.5 * v / rotor.rotor_radius * 30 / np.pi, np.zeros(v.size))
    meas = hidden({"wind_tunnel_blockage": {"blockage_area_ratio": 0.2}}, cond, 9010 + wide, channels=("power",
                                                                                                       "thrust"))
    d = run(meas, candidates=("wind_tunnel_blockage", "wind_speed_scale", "pitch_offset"), recalibrate=False)
    if wide:
        assert d.effect == "wind_tunnel_blockage", d.rounds[0]["reason"]
    else:
        assert d.effect == "ambiguous", d.rounds[0]["reason"]
        assert set(d.rounds[0]["ambiguous"]) == {"wind_tunnel_blockage", "wind_speed_scale"}
        # the measurement that separates them: another thrust coefficient (tip-speed ratio or pitch)
        best = d.rounds[0]["separate"]["probes"][0]
        assert best["kind"] == "another operating point" and best["separation"] > 3, best
        assert abs(best["tip_speed_ratio"] - 7.5) > 0.5 or abs(best["pitch"]) > 1.0, best
        assert "to tell them apart, measure" in d.rounds[0]["reason"] and "thrust coefficient" in d.rounds[0]["reason"]
        assert d.to_dict()["rounds"][0]["separate"]["probes"][0] == best
        # the words keep both candidates with their fitted values, and add no effect that was not added
        from calib.report.diagnosis_report import _summary_html, decision_words

        assert d.effects == [] and d.to_dict()["ambiguous"] == d.rounds[0]["ambiguous"]
        words = decision_words(d)
        assert "ambiguous between wind_tunnel_blockage (blockage_area_ratio " in words and \
            " and wind_speed_scale (wind_scale " in words and " ± " in words, words
        summary = "".join(_summary_html(d))
        assert "with the effect" not in summary and "neither added" in summary, summary


def test_diagnose_cli_writes_json_and_report(tmp_path, capsys):
    rotor = load_rotor("nrel5mw")
    meas = hidden({"pitch_offset": {"pitch_offset": 1.0}}, campaign(rotor), 9020, channels=("power", "thrust"))
    meas.write_csv(tmp_path / "data.csv")
    (tmp_path / "cfg.toml").write_text('[model]\nuse_tilt = false\n[diagnosis]\ncandidates = ["pitch_offset", '
                                       '"wind_speed_scale", "tip_loss"]\n[grid]\nalpha_nodes_deg = "auto"\n'
                                       'eta_nodes = [0.3, 0.6, 1.0]\n')
    assert cli_main(["diagnose", "--rotor", "nrel5mw", "--data", str(tmp_path / "data.csv"), "--out",
                     str(tmp_path / "out"), "--config", str(tmp_path / "cfg.toml")]) == 0
    d = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert d["effect"] == "pitch_offset" and d["effects"] == ["pitch_offset"]
    assert {"name", "parameters", "loglik", "bic", "weight"} <= set(d["candidates"][0])
    assert d["before"]["chi2_per_dof"] >= 5 and d["after"]["chi2_per_dof"] <= 1.5
    assert set(d["before"]["rms"]) == {"power", "thrust"}
    fitted = next(c for c in d["candidates"] if c["name"] == "pitch_offset")["parameters"][0]
    assert abs(fitted["value"] - 1.0) <= 3 * fitted["std"]
    html = (tmp_path / "out" / "report.html").read_text()
    assert "pitch_offset" in html and html.rstrip().endswith("</html>")
    assert "&lt; 1e-16" in html and "<td><" not in html       # a p-value below round-off, escaped (issue 35)
    # bad input: a clear message and a non-zero exit
    (tmp_path / "bad.toml").write_text("[diagnosis]\ncandidates = [\"ice\"]\n")
    assert cli_main(["diagnose", "--rotor", "nrel5mw", "--data", str(tmp_path / "data.csv"), "--out",
                     str(tmp_path / "o2"), "--config", str(tmp_path / "bad.toml")]) == 2
    assert "diagnosis.candidates" in capsys.readouterr().err


def test_diagnose_cli_on_a_table_without_sigma_columns_takes_the_noise_model_from_the_command_line(tmp_path, capsys):
    """Issue 35, item 4: an ordinary CSV (no _sigma columns) stops the documented command with the
    stated noise model, and ``--noise ml`` (the same key as [calibration] noise) lets it run."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"pitch_offset": {"pitch_offset": 1.0}}, campaign(rotor), 9021, channels=("power", "thrust"))
    meas.write_csv(tmp_path / "full.csv")
    lines = [ln for ln in (tmp_path / "full.csv").read_text().splitlines() if not ln.startswith("#")]
    head = lines[0].split(",")
    keep = [j for j, h in enumerate(head) if "_sigma" not in h]
    assert len(keep) < len(head)
    (tmp_path / "data.csv").write_text("\n".join(",".join(row.split(",")[j] for j in keep) for row in lines) + "\n")
    (tmp_path / "cfg.toml").write_text('[model]\nuse_tilt = false\n[diagnosis]\ncandidates = ["pitch_offset", '
                                       '"wind_speed_scale"]\nrecalibrate = false\n')
    args = ["diagnose", "--rotor", "nrel5mw", "--data", str(tmp_path / "data.csv"), "--config",
            str(tmp_path / "cfg.toml")]
    assert cli_main(args + ["--out", str(tmp_path / "known")]) == 2
    assert "sigma" in capsys.readouterr().err
    assert cli_main(args + ["--out", str(tmp_path / "ml"), "--noise", "ml"]) == 0
    d = json.loads((tmp_path / "ml" / "diagnosis.json").read_text())
    assert d["effect"] == "pitch_offset", d["rounds"][0]["reason"]
    assert any("noise model: ml" in line for line in (tmp_path / "ml" / "calib.log").read_text().splitlines())


def test_unknown_candidate_refused():
    with pytest.raises(InputError, match="valid"):
        DiagnosisSettings(candidates=("icing",)).validate()


@pytest.mark.statistics
@pytest.mark.parametrize("effect", sorted(TRUTH))
def test_every_hidden_effect_is_named(effect):
    rotor = load_rotor("nrel5mw")
    d = run(hidden({effect: TRUTH[effect]}, campaign(rotor), 9100))
    assert d.named_first == effect, d.rounds[0]["reason"]
    assert (d.model_form[:1] == [effect] and d.effect == "none") if effect in MODEL_FORM else d.effect == effect
    assert d.before["chi2_per_dof"] >= 5 and d.after["chi2_per_dof"] <= 1.5, (d.before, d.after)


@pytest.mark.statistics
def test_stall_delay_named_when_the_truth_uses_another_form():
    """Truth Du–Selig, library restricted to Snel's form: still rotational augmentation."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"rotational_augmentation": {"stall_delay_strength": 1.0}}, campaign(rotor), 9200,
                  options={"rotational_augmentation": {"variant": "du_selig"}})
    d = run(meas, candidate_options={"rotational_augmentation": {"variant": "snel"}})
    assert d.effect == "rotational_augmentation", d.rounds[0]["reason"]


@pytest.mark.statistics
def test_tip_loss_named_when_the_truth_uses_another_form():
    """Truth: the tip factor with g = 1 on the element forces (Prandtl's own factor applied to
    the forces, no λ dependence of g); the library fits Shen's g(λ) = exp(−0.125 (Bλ − 21)) + 0.1."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"tip_loss": {"tip_loss_strength": 1.0}}, campaign(rotor), 9102,
                  options={"tip_loss": {"c1": 0.0, "c2": 0.0, "c3": 0.0}})
    d = run(meas, recalibrate=False)
    assert d.named_first == "tip_loss" and d.model_form == ["tip_loss"], d.rounds[0]["reason"]
    assert "model form (the BEM's own induction model, not a missing physical effect)" in d.rounds[0]["reason"]
    assert d.with_effects["chi2_per_dof"] < 0.5 * d.before["chi2_per_dof"], (d.before, d.with_effects)
    # what Shen's form leaves of another tip-loss form is not a second, physical effect (issue 37, item 4):
    # before, a Reynolds-number effect stood in for it and took the gap below 0.2 of the nominal's
    assert d.effects == ["tip_loss"] and "would explain only" in d.rounds[-1]["reason"], d.rounds[-1]["reason"]


@pytest.mark.statistics
def test_two_hidden_effects_are_both_named():
    rotor = load_rotor("nrel5mw")
    meas = hidden({"rotational_augmentation": {"stall_delay_strength": 1.0}, "pitch_offset": {"pitch_offset": 1.0}},
                  campaign(rotor), 9300)
    d = run(meas)
    assert set(d.effects) == {"rotational_augmentation", "pitch_offset"}, [r["reason"] for r in d.rounds]


FMU_QUIET = dict(tower_shadow=False, shear=False, yaw=False, flexible_blades=False, gravity=False, skewed_wake=False,
                 dynamic_inflow=False)


@pytest.mark.statistics
@pytest.mark.parametrize("effect", ["rotational_augmentation", "pitch_offset"])
def test_hidden_effect_in_fmu_data_is_named(effect):
    """Data from the turbine FMU (variant A: its own element solver, azimuth stepping and
    averaging, i.e. model-form differences from the native BEM) with one effect switched on,
    1 % noise; the native-BEM diagnosis names it."""
    from calib.fmu.build import build_fmu, mapping_path
    from calib.fmu.model import FmuModel

    rotor = load_rotor("nrel5mw")
    switches = dict(FMU_QUIET, tip_loss=True, hub_loss=True)
    params = []
    if effect == "rotational_augmentation":
        switches["stall_delay"] = "snel"
    else:
        params = ["pitch_offset_blade1", "pitch_offset_blade2", "pitch_offset_blade3"]
    fmu = FmuModel(build_fmu("A", rotor), mapping_path("A"), channels=["power", "thrust", "root_flap_moment"],
                   parameters=params, corrections=False, switches=switches,
                   settings={"shaft_tilt": 0.0, "max_internal_step": 0.05, "max_azimuth_step": 5.0},
                   steady=dict(steps_per_revolution=36, settle_revolutions=1, average_revolutions=2))
    p = np.array([1.0 if q.name.startswith("pitch_offset") else q.nominal for q in fmu.parameters])
    cond = campaign(rotor, tsr=np.linspace(3.0, 11.0, 7), pitch=(-1.0, 3.0, 7.0))
    meas = synthesize(fmu, p, cond, relative_sigma={c: 0.01 for c in ("power", "thrust", "root_flap_moment")},
                      seed=9400)
    d = run(meas)
    assert d.effect == effect, d.rounds[0]["reason"]


def test_a_candidate_that_cannot_act_on_the_rotor_is_reported_not_applicable():
    """The Phase VI rotor has no operating schedule, so the Reynolds-number effect has no
    reference Re: it is listed as not applicable and the diagnosis goes on."""
    rotor = load_rotor("phase_vi")
    T, P = np.meshgrid([3.0, 4.0, 5.0, 6.0], [0.0, 4.0], indexing="ij")
    v = 72.0 * np.pi / 30 * rotor.rotor_radius / T.ravel()
    cond = OperatingConditions(v, np.full(v.size, 72.0), P.ravel())
    meas = hidden({"pitch_offset": {"pitch_offset": 1.0}}, cond, 9030, channels=("torque", "thrust"), rotor=rotor)
    d = diagnose(rotor, meas, CorrectionGrid([0.0, 10.0, 20.0], [0.4, 0.8, 1.0]), SETTINGS,
                 CalibrationSettings(cd_min=0.003),
                 DiagnosisSettings(candidates=("reynolds_number", "pitch_offset"), recalibrate=False))
    assert d.effect == "pitch_offset"
    assert any("reynolds_number not applicable" in n for n in d.notes)


def test_a_nominal_model_that_passes_the_global_test_gets_no_effect():
    """A 0.4 % wind-speed scale under 1 % noise (seed 9602): the nominal model passes the global χ²
    test (p = 0.26), though the likelihood ratio of wind_speed_scale alone is significant. With
    the stated noise the global test gates: `none`, no candidate fitted. The same data are given
    the effect when the global test is set to fail them (significance above their p-value)."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"wind_speed_scale": {"wind_scale": 1.004}}, campaign(rotor), 9602)
    cal = CalibrationSettings(cd_min=0.003, noise="known")
    d = diagnose(rotor, meas, GRID, SETTINGS, cal, DiagnosisSettings(recalibrate=False, model_form_tolerance=0.0))
    assert 0.01 < d.before["p_value"] < 0.3
    assert d.effect == "none" and d.candidates == [] and d.rounds[0]["verdict"] == "none"
    assert "consistent with the noise" in d.rounds[0]["reason"]
    ungated = diagnose(rotor, meas, GRID, SETTINGS, cal, DiagnosisSettings(recalibrate=False, significance=0.3,
                                                                          model_form_tolerance=0.0))
    assert ungated.effect == "wind_speed_scale"


def test_a_recalibration_that_ends_above_its_start_is_not_kept(monkeypatch):
    """The nominal field is inside the recalibration's search space: a recalibration that ends with
    a larger χ² than the model with the named effect (forced here) is rejected with a note."""
    import calib.diagnosis.core as D

    real = D.Calibrator

    class Worse(real):
        def run(self):
            res = super().run()
            if self.name == "recalibration":
                res.fit.model_after = res.fit.model_after * 1.05
            return res

    monkeypatch.setattr(D, "Calibrator", Worse)
    rotor = load_rotor("nrel5mw")
    d = run(hidden({"pitch_offset": TRUTH["pitch_offset"]}, campaign(rotor), 9603), candidates=("pitch_offset",),
            max_effects=1)
    assert d.effect == "pitch_offset" and d.recalibration is None
    assert any("recalibration ended with χ²" in n and "not kept" in n for n in d.notes)
    assert d.after["chi2"] == d.with_effects["chi2"]


@pytest.mark.parametrize("change, tolerance, size, exceeds, text", [
    (0.021, 0.01, 0.021, True, "+2.1 % power at 8 m/s (tolerance 1 %)"),
    (0.008, 0.01, 0.008, False, "+0.8 % power at 8 m/s (tolerance 1 %)"),
    (-0.03, 0.0, 0.03, True, "-3 % power at 8 m/s"),
])
def test_effect_size_against_the_model_form_tolerance(change, tolerance, size, exceeds, text):
    from calib.diagnosis.figures_of_merit import effect_size

    base = np.array([[1.0e6, 5.0e5], [2.0e6, 6.0e5], [1.0e3, 7.0e5]])    # the last power is below 10 % of the largest
    values = base.copy()
    values[1, 0] *= 1 + change
    values[2, 0] *= 1 + 10 * change                                    # not a usable point: not counted
    got = effect_size(values, base, np.array([tolerance, tolerance]), ["power", "thrust"], np.array([6.0, 8.0, 4.0]))
    assert got[0] == pytest.approx(size, rel=1e-12) and got[2] is exceeds and got[1] == text


def test_a_misfit_within_the_model_form_tolerance_names_nothing():
    """A 1 % wind-speed scale (about 3 % in power) under 1 % noise fails the global test and is
    named; with a 5 % model-form tolerance the same data are within it: `none`, said so."""
    rotor = load_rotor("nrel5mw")
    meas = hidden({"wind_speed_scale": {"wind_scale": 1.01}}, campaign(rotor), 9604)
    cal = CalibrationSettings(cd_min=0.003, noise="known")
    plain = diagnose(rotor, meas, GRID, SETTINGS, cal, DiagnosisSettings(recalibrate=False, max_effects=1))
    assert plain.effect == "wind_speed_scale" and "effect +" in plain.rounds[0]["reason"]
    tolerant = diagnose(rotor, meas, GRID, SETTINGS, cal, DiagnosisSettings(
        recalibrate=False, max_effects=1, model_form_tolerance={"default": 0.05}))
    assert tolerant.effect == "none" and "within the model-form tolerance" in tolerant.rounds[0]["reason"]
    with pytest.raises(InputError, match="model_form_tolerance"):
        DiagnosisSettings(model_form_tolerance=1.5).validate()


def test_a_parameter_whose_derivative_vanishes_at_nominal_is_fitted_away_from_it():
    """Erosion's onset span has zero derivative at nominal (no damage, no onset to see): the
    candidate fit still moves it from its nominal r/R 0.7 to the truth's 0.45."""
    rotor = load_rotor("nrel5mw")
    truth = {"erosion_onset_eta": 0.45, **TRUTH["leading_edge_erosion"]}
    cond = campaign(rotor)
    model = BemModel(rotor, None, CHANNELS, SETTINGS, (), effects=[make_effect("leading_edge_erosion")])
    _, G = model.jacobian(np.array([q.nominal for q in model.parameters]), cond)
    assert np.all(G[:, :, 0] == 0.0)                               # d/d(onset) at nominal
    d = run(hidden({"leading_edge_erosion": truth}, cond, 9605), candidates=("leading_edge_erosion",),
            max_effects=1, recalibrate=False, candidate_options={"leading_edge_erosion": {"variant": "stall"}})
    fit = d.candidates[0]
    onset = next(q for q in fit.parameters if q["name"] == "erosion_onset_eta")
    assert d.effect == "leading_edge_erosion" and fit.status == "converged"
    assert abs(onset["value"] - 0.45) < max(3 * onset["std"], 0.03), onset


class _ProductModel:
    """Outputs base·(1 + a·b·λ/7 + a²·(λ/7)²/4): every derivative in (a, b) vanishes at the nominal
    (0, 0), where Gauss-Newton cannot take a step (a zero-magnitude effect's shape parameters)."""

    def __init__(self):
        from calib.types import Channel, Parameter
        self.parameters = (Parameter("a", 0.0, -3.0, 3.0, 0.5, "-", "effect"),
                           Parameter("b", 0.0, -3.0, 3.0, 0.5, "-", "effect"))
        self.channels = (Channel("power", "W"), Channel("thrust", "N"))
        self.capabilities = Capabilities("ProductModel", derivatives="exact")

    def _parts(self, conditions):
        lam = conditions.rotor_speed * np.pi / 30.0 * 60.0 / conditions.wind_speed / 7.0
        return np.column_stack([1e6 * lam, 4e5 + 0 * lam]), lam

    def evaluate(self, p, conditions):
        from calib.types import Evaluation
        base, lam = self._parts(conditions)
        a, b = p
        factor = 1.0 + a * b * lam + a * a * lam ** 2 / 4.0
        return Evaluation(base * factor[:, None], np.zeros(len(conditions), int), ("",) * len(conditions),
                          self.channels, {})

    def jacobian(self, p, conditions):
        base, lam = self._parts(conditions)
        a, b = p
        G = np.stack([base * (b * lam + a * lam ** 2 / 2.0)[:, None], base * (a * lam)[:, None]], axis=-1)
        return self.evaluate(p, conditions), G


def test_a_candidate_whose_every_derivative_vanishes_at_nominal_is_started_again_away_from_it():
    """Gauss-Newton cannot leave a point where every derivative vanishes: the candidate fit ends
    on its start, is started again one scale away, and the second start (kept) finds the truth."""
    from calib.diagnosis.candidate_parameters import away_start
    from calib.diagnosis.naming import fit_task
    model = _ProductModel()
    J = model.jacobian(np.zeros(2), campaign(load_rotor("nrel5mw")))[1]
    assert np.all(J == 0.0)
    truth = np.array([1.0, 0.5])
    meas = synthesize(model, truth, campaign(load_rotor("nrel5mw")), relative_sigma={"power": 0.01, "thrust": 0.01},
                      seed=9611)
    known = CalibrationSettings(noise="known", retain="all")
    out = fit_task({"name": "product", "model": model, "measurements": meas, "settings": known, "own": [0, 1]})
    a, b = out["result"].estimate.p_hat
    assert out["start_note"].startswith("second start kept"), out["start_note"]
    assert abs(a * b - 0.5) < 0.05 and abs(a * a - 1.0) < 0.1, (a, b)
    from calib.calibration import Calibrator
    with pytest.raises(InputError, match="start"):
        Calibrator(model, meas, known, start=np.array([1.0]))
    # the away start moves toward the side with more room, by one scale at most half the room
    assert np.allclose(away_start(np.array([0.0, 2.9]), np.array([-3.0, -3.0]), np.array([3.0, 3.0]),
                                  np.array([0.5, 0.5]), [0, 1]), [0.5, 2.4])
    assert np.allclose(away_start(np.array([0.0]), np.array([0.0]), np.array([0.4]), np.array([0.5]), [0]), [0.2])


def _namer(monkeypatch, ambiguity_pattern=0.1):
    """A naming step with nothing but settings (for the verdict rules alone)."""
    from calib.diagnosis import naming as D
    monkeypatch.setattr(D, "separation_of", lambda namer, a, b: {"text": f"separate {a.effect} from {b.effect}"})

    class Family:
        def names_of(self, base):
            return []
    y0 = np.ones((10, 2))
    return D.Namer(Family(), None, y0, 100.0, np.zeros_like(y0), DiagnosisSettings(ambiguity_pattern=ambiguity_pattern),
                    None, None, None, None, lambda s: None)


def _fit(name, bic, agreement):
    from calib.diagnosis.result import CandidateFit
    return CandidateFit(name, [], bic - 2.0, 1, -0.5 * bic, bic, 100.0 - bic, 1e-9, True, pattern_agreement=agreement,
                        status="converged", effect=name, effect_text="+3 % power")


def test_two_candidates_equal_by_bic_are_told_apart_by_their_pattern_or_called_ambiguous(monkeypatch):
    """Equal BIC and equal pattern agreement: ambiguous, with the separating measurement; equal BIC but
    patterns apart by more than ``ambiguity_pattern``: the better-agreeing one is named, even with
    the (slightly) worse BIC; BIC apart by more than ``ambiguity_bic``: the better BIC is named."""
    rnd, best = _namer(monkeypatch)._judge([_fit("tip_loss", 20.0, 0.90), _fit("lift_offset", 21.0, 0.86)])
    assert best is None and rnd["verdict"] == "ambiguous" and set(rnd["ambiguous"]) == {"tip_loss", "lift_offset"}
    assert "separate tip_loss from lift_offset" in rnd["reason"] and rnd["separate"]["text"] in rnd["reason"]
    rnd, best = _namer(monkeypatch)._judge([_fit("tip_loss", 20.0, 0.50), _fit("lift_offset", 21.0, 0.90)])
    assert best.effect == "lift_offset" and "agrees better with the localized correction (0.90 against 0.50" in \
        rnd["reason"]
    rnd, best = _namer(monkeypatch, ambiguity_pattern=0.5)._judge([_fit("tip_loss", 20.0, 0.50),
                                                                    _fit("lift_offset", 21.0, 0.90)])
    assert rnd["verdict"] == "ambiguous"
    rnd, best = _namer(monkeypatch)._judge([_fit("tip_loss", 20.0, 0.50), _fit("lift_offset", 30.0, 0.90)])
    assert best.effect == "tip_loss"
    with pytest.raises(InputError, match="ambiguity_pattern"):
        DiagnosisSettings(ambiguity_pattern=-1).validate()


def test_a_later_effect_is_named_only_when_it_explains_most_of_the_misfit_left(monkeypatch):
    """Issue 37, item 4: after a first effect, a candidate must explain (Λ) at least
    LATER_EFFECT_SHARE of χ² − dof of the model with the first effect, beyond the noise (the one-sided
    share test of calib.diagnosis.share at the diagnosis' significance); a first effect at a bound
    is said to may not fit in form."""
    from calib.diagnosis.naming import LATER_EFFECT_SHARE
    from calib.diagnosis.share import share_test

    class Family:
        def names_of(self, base):
            return list(base)

        def n_parameters(self, base):
            return len(base)

    def namer(first_at_bound=False):
        n = _namer(monkeypatch)
        n.family = Family()
        first = _fit("rotational_augmentation", 10.0, 0.9)
        if first_at_bound:
            first.parameters = [{"name": "stall_delay_strength", "at_bound": "upper", "upper": 3.0, "unit": "-"}]
            first.at_bound = ["stall_delay_strength"]
        n.named, n._named_fits, n.base_effects = ["rotational_augmentation"], [first], ["ra"]
        n.base_chi2 = n.n_res - 1 + 100.0          # χ² − dof = 100 left with the first effect
        return n

    n = namer()
    # Λ where the test's z reaches its critical value (one candidate compared: Φ⁻¹(1 − significance))
    z_needed = share_test(0.0, 1, n.base_chi2, n.n_res - 1, LATER_EFFECT_SHARE, n.dset.significance).z_needed
    edge = next(lr for lr in np.arange(60.0, 100.0, 0.01)
                if share_test(lr, 1, n.base_chi2, n.n_res - 1, LATER_EFFECT_SHARE, n.dset.significance).passed)
    assert edge > LATER_EFFECT_SHARE * 100 + 10      # 66 % of so small a misfit is within its noise
    for lr, named in ((LATER_EFFECT_SHARE * 100 + 1, False), (edge - 0.1, False), (edge + 0.1, True)):
        fit = _fit("lift_offset", 20.0, 0.6)
        fit.lr_statistic = lr
        rnd = {"verdict": "lift_offset", "reason": "lift_offset: ..."}
        best = namer()._earns_place(rnd, fit)
        assert (best is fit) == named and rnd["verdict"] == ("lift_offset" if named else "none")
        if not named:
            assert f"would explain only {lr:.0f} % ± " in rnd["reason"]
            assert f"(needs {z_needed:.2g})" in rnd["reason"]
    fit = _fit("lift_offset", 20.0, 0.6)
    fit.lr_statistic = 99.0
    rnd = {"verdict": "lift_offset", "reason": "lift_offset: ..."}
    assert namer(first_at_bound=True)._earns_place(rnd, fit) is fit
    assert ("rotational_augmentation sits at a bound (at bound: stall_delay_strength = 3 (upper bound)): its form "
            "may not fit the data, and lift_offset may stand in for that mismatch") in rnd["reason"]


def test_the_separating_probe_is_where_the_two_predictions_differ_most_against_the_noise():
    from calib.diagnosis.separation import probe_conditions, separating_probes
    measured = OperatingConditions(np.array([8.0, 10.0]), np.array([10.0, 12.0]), np.array([0.0, 0.0]))
    probes = probe_conditions(measured, 63.0)
    lam = probes.tip_speed_ratio(63.0)
    # no schedule: the campaign's rotor speeds (10, 11, 12 rpm) at wind speeds from half the lowest to 1.5
    # times the highest measured
    assert set(np.round(probes.rotor_speed, 6)) == {10.0, 11.0, 12.0} and set(probes.pitch) == {-2.0, 0.0, 4.0}
    assert probes.wind_speed.min() >= 4.0 and probes.wind_speed.max() <= 15.0 and len(probes) >= 30
    assert lam.min() >= 0.75 * measured.tip_speed_ratio(63.0).min() - 1e-9
    both = OperatingConditions(*(np.concatenate([getattr(measured, f), getattr(probes, f)])
                                 for f in ("wind_speed", "rotor_speed", "pitch")))
    a = np.ones((len(both), 2)) * [1e6, 5e5]
    b = a.copy()
    b[1, 1] *= 1.05             # a measured point, in the unmeasured channel: 5 % = 2.5 noise
    b[2 + 17, 0] *= 1.10        # a probe, in the measured channel: 10 % = 5 noise
    found = separating_probes(a, b, both, ["power", "fn@0.70"], ["power"], {"power": 0.02}, 2, 63.0)
    assert [(p.kind, p.channel) for p in found] == [("another operating point", "power"),
                                                    ("measured point, another channel", "fn@0.70")]
    assert np.isclose(found[0].separation, 0.1 / 0.02 / 1.05, rtol=1e-12)
    assert np.isclose(found[1].separation, 0.05 / 0.02 / 1.025, rtol=1e-12)
    assert np.isclose(found[0].tip_speed_ratio, lam[17]) and "power at λ" in found[0].words(("x", "y"), "W")


def test_separation_probes_keep_to_the_rotors_operating_limits():
    """Issue 35: the probe proposed to separate two effects ran the NREL 5-MW at 24.6 rpm, where its
    schedule caps it at 12.1 rpm. Probes keep to the schedule's rotor speeds and cut-in to cut-out."""
    from calib.diagnosis.separation import probe_conditions, probe_limits

    rotor = load_rotor("nrel5mw")
    sch = rotor.schedule
    measured = campaign(rotor, tsr=np.linspace(3.0, 11.0, 9), pitch=(-1.0, 2.0, 5.0, 8.0))
    probes = probe_conditions(measured, rotor.rotor_radius, sch)
    assert len(probes) > 0
    assert probes.rotor_speed.min() >= sch.min_rotor_speed - 1e-9 and probes.rotor_speed.max() <= sch.max_rotor_speed + 1e-9
    assert probes.wind_speed.min() >= sch.cut_in - 1e-9 and probes.wind_speed.max() <= sch.cut_out + 1e-9
    assert f"rotor speed {sch.min_rotor_speed:.3g}–{sch.max_rotor_speed:.3g} rpm" in probe_limits(measured, sch)[2]


def test_an_ambiguous_pair_of_physical_effects_is_weighed_over_the_model_form(monkeypatch):
    """Model form first (issue 37): a round ambiguous between two physical effects while a model-form
    candidate is significant names the model form when neither earns its place on top of it (the
    round's reason keeps what was ambiguous); when one does, the round stays ambiguous as it was; with no
    significant model-form candidate nothing is weighed."""
    n = _namer(monkeypatch)
    re_fit, ra_fit, form = (_fit("reynolds_number", 20.0, 0.6), _fit("rotational_augmentation", 21.0, 0.7),
                            _fit("momentum_balance", 40.0, 0.2))
    form.kind = "model_form"
    asked = []

    def judged(outcome):
        def over(round_no, rnd, best, forms, fits):
            asked.append((best.effect, [f.effect for f in forms]))
            rnd.update(verdict="changed", reason="weighed")
            return outcome
        return over

    def round_record():
        return {"verdict": "ambiguous", "ambiguous": ["reynolds_number", "rotational_augmentation"],
                "reason": "reynolds_number and rotational_augmentation fit about equally well", "separate": {}}

    n._over_model_form = judged(form)
    rnd = round_record()
    assert n._ambiguous_with_model_form(0, rnd, [re_fit, ra_fit, form]) is form
    assert asked == [("reynolds_number", ["momentum_balance"])]          # the better of the pair, by BIC
    assert "ambiguous" not in rnd and "separate" not in rnd
    assert rnd["reason"] == "weighed (the round was ambiguous: reynolds_number and rotational_augmentation fit " \
                            "about equally well)"
    n._over_model_form = judged(re_fit)
    rnd = round_record()
    assert n._ambiguous_with_model_form(0, rnd, [re_fit, ra_fit, form]) is None and rnd == round_record()
    assert n._over_form is None
    form.significant = False
    asked.clear()
    assert n._ambiguous_with_model_form(0, round_record(), [re_fit, ra_fit, form]) is None and not asked
