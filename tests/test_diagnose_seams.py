"""Seams of ``calib diagnose`` (issue 24): a fitted parameter on its bound, a failure in a later
naming round, the unit check, and ``[diagnosis] channels`` (seeds 9302, 9400+, used nowhere else).

The end-to-end cases share one small campaign: the NREL 5-MW with a hidden negative lift offset
of -0.3, which leading-edge erosion (the only lift-changing candidate offered) can only follow
by pushing its onset span to the lower bound; pitch offset then remains for a second round.
"""

import json

import numpy as np
import pytest
from test_diagnosis import campaign, hidden

from calib.cli import main as cli_main
from calib.diagnosis import bem_family, candidate_parameters, naming, verdict
from calib.diagnosis.result import CandidateFit
from calib.effects import EFFECTS, make_effect
from calib.errors import InputError, ModelError

# in family (the library's own effects on its own BEM): no model-form tolerance
CONFIG = ('[model]\nuse_tilt = false\n[grid]\nalpha_nodes_deg = "auto"\neta_nodes = [0.3, 0.6, 1.0]\n'
          '[diagnosis]\nrecalibrate = false\nmodel_form_tolerance = 0.0\n')


def _ulps_outside(bound: float, direction: float, n: int = 3) -> float:
    """``bound`` moved ``n`` units in the last place toward ``direction`` (±inf)."""
    v = bound
    for _ in range(n):
        v = np.nextafter(v, direction)
    return float(v)


def _every_parameter():
    for name in EFFECTS:
        if name == "correction_field":
            continue
        for q in make_effect(name).parameters():
            yield name, q


# ----------------------------------------------------------------------------- (a) unit level
def test_fitted_value_past_a_bound_by_round_off_becomes_the_bound_as_nominal():
    """Every effect parameter: a fitted value a few ulp past either bound is the bound as the next
    round's nominal (on main: InputError 'nominal ... outside its bounds')."""
    checked = 0
    for name, q in _every_parameter():
        spec = make_effect(name).spec()
        for bound, away in ((q.lower, -np.inf), (q.upper, np.inf)):
            value = _ulps_outside(bound, away)
            assert not (q.lower <= value <= q.upper)
            fixed = bem_family._fixed_effect(spec, {q.name: value})
            nominal = {p.name: p.nominal for p in fixed.parameters()}[q.name]
            assert nominal == bound
            assert q.lower <= fixed.spec()["options"]["nominal"][q.name] <= q.upper
            checked += 1
    assert checked >= 2 * 10


def test_effect_nominal_tolerates_round_off_only():
    """The effect accepts a nominal a few ulp past a bound (as the bound) and still refuses one
    that is truly outside, naming the parameter."""
    q = {p.name: p for p in make_effect("leading_edge_erosion").parameters()}["erosion_lift_loss"]
    e = make_effect("leading_edge_erosion", nominal={q.name: _ulps_outside(q.lower, -np.inf)})
    assert {p.name: p.nominal for p in e.parameters()}[q.name] == q.lower
    with pytest.raises(InputError, match="nominal.erosion_lift_loss"):
        make_effect("leading_edge_erosion", nominal={q.name: q.lower - 1e-3 * q.scale})


def test_at_bound_is_a_fraction_of_the_parameter_scale():
    tol = candidate_parameters.AT_BOUND_TOLERANCE
    lo, hi, scale = -0.2, 0.5, 0.05
    assert candidate_parameters.bound_side(lo + 0.5 * tol * scale, lo, hi, scale) == "lower"
    assert candidate_parameters.bound_side(_ulps_outside(lo, -np.inf), lo, hi, scale) == "lower"
    assert candidate_parameters.bound_side(hi - 0.5 * tol * scale, lo, hi, scale) == "upper"
    assert candidate_parameters.bound_side(lo + 2 * tol * scale, lo, hi, scale) == ""
    assert candidate_parameters.bound_side(hi - 2 * tol * scale, lo, hi, scale) == ""
    # relative to the scale, not to the bound: a wider scale widens the band
    assert candidate_parameters.bound_side(lo + 2 * tol * scale, lo, hi, 4 * scale) == "lower"


def test_candidate_table_and_verdict_say_at_bound():
    from calib.report.diagnosis_report import _candidate_rows

    params = [{"name": "erosion_onset_eta", "value": 0.2999999999999998, "std": 0.01, "unit": "-", "nominal": 0.7,
               "lower": 0.3, "upper": 0.95, "at_bound": "lower"},
              {"name": "erosion_lift_loss", "value": 0.1, "std": 0.02, "unit": "-", "nominal": 0.0,
               "lower": -0.2, "upper": 0.5, "at_bound": ""}]
    fit = CandidateFit("leading_edge_erosion", params, 10.0, 2, -5.0, 12.0, 100.0, 1e-9, True, status="converged",
                       effect="leading_edge_erosion", at_bound=["erosion_onset_eta"])
    suffix = verdict.bound_suffix(fit)
    assert "at bound: erosion_onset_eta = 0.3 (lower bound)" in suffix and "erosion_lift_loss" not in suffix

    class D:
        rounds = [{"candidates": [fit]}]

    (row,) = _candidate_rows(D)
    assert row.cells[-1].startswith('<span class="nb">0.3 at bound</span>')     # the bound, not the estimate
    assert "erosion_onset_eta = 0.3 ± 0.01 (at lower bound)" in row.detail and row.detail.endswith("Fit: converged.")


# ----------------------------------------------------------------------------- end to end
@pytest.fixture(scope="module")
def lift_data(tmp_path_factory):
    from calib.rotor.library import load_rotor

    path = tmp_path_factory.mktemp("seams") / "lift.csv"
    hidden({"lift_offset": {"lift_offset": -0.3}}, campaign(load_rotor("nrel5mw")), 9302,
           channels=("power", "thrust")).write_csv(path)
    return path


def _diagnose(tmp_path, data, config_text, *extra, name="out"):
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text(config_text)
    out = tmp_path / name
    code = cli_main(["diagnose", "--rotor", "nrel5mw", "--data", str(data), "--out", str(out), "--config", str(cfg),
                     "--quiet", *extra])
    return code, out


def _past_the_bound(fit_task):
    """``fit_task`` whose estimates on a bound end 3 ulp past it, as round-off may leave them."""
    def task(t):
        out = fit_task(t)
        res = out["result"]
        band = 1e-3 * res.estimate.scale          # within the at-bound band (written out: main has no bound_side)
        for j in range(res.n_params):
            if res.estimate.p_hat[j] <= res.estimate.lower[j] + band[j]:
                res.estimate.p_hat[j] = _ulps_outside(res.estimate.lower[j], -np.inf)
            elif res.estimate.p_hat[j] >= res.estimate.upper[j] - band[j]:
                res.estimate.p_hat[j] = _ulps_outside(res.estimate.upper[j], np.inf)
        return out
    return task


def test_diagnose_names_an_effect_on_its_bound_and_goes_on(tmp_path, lift_data, monkeypatch):
    """Erosion follows the hidden lift offset to its lower onset bound; the estimate ends past
    the bound by round-off (made certain here), which on main stopped the run with exit 2."""
    monkeypatch.setattr(naming, "fit_task", _past_the_bound(naming.fit_task))
    # erosion's near-stall form, which can follow the offset only with its onset on the bound
    code, out = _diagnose(tmp_path, lift_data, CONFIG + 'candidates = ["leading_edge_erosion", "pitch_offset"]\n'
                          'candidate_options = { leading_edge_erosion = { variant = "stall" } }\n')
    assert code == 0
    d = json.loads((out / "diagnosis.json").read_text())
    assert d["effects"][0] == "leading_edge_erosion" and len(d["rounds"]) == 2 and d["failure"] == ""
    ero = next(c for c in d["rounds"][0]["candidates"] if c["effect"] == "leading_edge_erosion")
    onset = next(q for q in ero["parameters"] if q["name"] == "erosion_onset_eta")
    assert onset["at_bound"] == "lower" and ero["at_bound"] == ["erosion_onset_eta"]
    assert "at bound: erosion_onset_eta" in d["rounds"][0]["reason"]
    assert d["rounds"][1]["base"] == ["leading_edge_erosion"]       # the next round ran on top of it
    html = (out / "report.html").read_text()
    assert "(at lower bound)" in html and "at bound: erosion_onset_eta" in html


def test_a_failure_in_round_2_keeps_round_1_and_exits_0(tmp_path, lift_data, monkeypatch, capsys):
    original = bem_family.BemFamily.candidate_model

    def fails_on_top_of_an_effect(self, base, effect):
        if base:
            raise ModelError("injected failure of a round-2 model")
        return original(self, base, effect)

    monkeypatch.setattr(bem_family.BemFamily, "candidate_model", fails_on_top_of_an_effect)
    # round 1 names one of two candidates that end inside their bounds; round 2 fails
    text = CONFIG + 'candidates = ["wind_speed_scale", "pitch_offset"]\n'
    code, out = _diagnose(tmp_path, lift_data, text)
    assert code == 0
    d = json.loads((out / "diagnosis.json").read_text())
    (named,) = d["effects"]
    assert d["effect"] == named and named in ("wind_speed_scale", "pitch_offset")
    assert [r["verdict"] for r in d["rounds"]] == [named, "failed"]
    assert "injected failure" in d["rounds"][1]["reason"] and "round 2" in d["failure"]
    assert d["with_effects"]["chi2_per_dof"] < d["before"]["chi2_per_dof"]
    html = (out / "report.html").read_text()
    assert "Stopped early" in html and "injected failure" in html and named in html
    assert "stopped early" in (out / "calib.log").read_text()
    # resumed: the same diagnosis from the record, and the same exit code
    assert cli_main(["diagnose", "--resume", str(out), "--quiet"]) == 0
    assert json.loads((out / "diagnosis.json").read_text())["rounds"][1]["verdict"] == "failed"


# ----------------------------------------------------------------------------- (c) unit check
def _kw_labelled_w(src, dst):
    """``src`` with power and its σ divided by 1000, the header still saying W."""
    lines = src.read_text().splitlines()
    rows = [ln for ln in lines if not ln.startswith("#")]
    head = rows[0].split(",")
    cols = [j for j, h in enumerate(head) if h.split(" [")[0] in ("power", "power_sigma")]
    assert all("[W]" in head[j] for j in cols) and len(cols) == 2
    out = [rows[0]]
    for row in rows[1:]:
        v = row.split(",")
        for j in cols:
            v[j] = repr(float(v[j]) / 1000.0)
        out.append(",".join(v))
    dst.write_text("\n".join(out) + "\n")
    return dst


def test_kw_labelled_as_w_stops_diagnose_unless_forced(tmp_path, lift_data, capsys):
    data = _kw_labelled_w(lift_data, tmp_path / "kw.csv")
    # the forced diagnosis is of data 1000 times off: a short localization is enough here
    text = (CONFIG + 'candidates = ["pitch_offset"]\nmax_effects = 1\n[calibration]\nsecond_start = false\n'
            'prior_check = false\ncurvature_samples = 0\nmax_relinearizations = 1\n')
    code, out = _diagnose(tmp_path, data, text)
    err = capsys.readouterr().err
    assert code == 2
    assert "kw.csv" in err and "field 'power'" in err and "10⁻³" in err and "--force" in err
    assert not (out / "diagnosis.json").exists()
    code, out = _diagnose(tmp_path, data, text, "--force", name="forced")
    assert code == 0
    d = json.loads((out / "diagnosis.json").read_text())
    assert any("overridden by force" in n and "power" in n for n in d["notes"])
    # a forced diagnosis resumes forced, without --force again
    assert cli_main(["diagnose", "--resume", str(out), "--quiet"]) == 0
    assert "model calls: 0 computed" in (out / "calib.log").read_text().split("resuming")[-1]


# ----------------------------------------------------------------------------- (d) channels
def test_diagnosis_channels_restrict_the_diagnosis(tmp_path, lift_data, capsys):
    text = CONFIG + 'candidates = ["pitch_offset"]\nmax_effects = 1\nchannels = ["power"]\n'
    code, out = _diagnose(tmp_path, lift_data, text)
    assert code == 0
    d = json.loads((out / "diagnosis.json").read_text())
    assert d["channels"] == ["power"] and set(d["before"]["rms"]) == {"power"}
    code, _ = _diagnose(tmp_path, lift_data, CONFIG + 'channels = ["power", "root_flap_moment"]\n', name="bad")
    err = capsys.readouterr().err
    assert code == 2 and "diagnosis.channels" in err and "root_flap_moment" in err


def test_fluid_density_fills_a_table_without_air_density(tmp_path, lift_data, monkeypatch):
    """As in ``calib run``: ``[fluid] density`` is the air density of points whose table has no
    ``air_density`` column (diagnose read 1.225 kg/m^3 whatever the config said)."""
    import calib.diagnosis.command

    lines = [ln.split(",") for ln in lift_data.read_text().splitlines() if not ln.startswith("#")]
    keep = [j for j, h in enumerate(lines[0]) if not h.startswith("air_density")]
    assert len(keep) == len(lines[0]) - 1
    data = tmp_path / "no_density.csv"
    data.write_text("\n".join(",".join(row[j] for j in keep) for row in lines) + "\n")
    seen = {}

    class Stop(Exception):
        pass

    def capture(rotor, meas, *args, **kwargs):
        seen["density"] = np.asarray(meas.conditions.air_density, float)
        raise Stop

    monkeypatch.setattr(calib.diagnosis.command, "diagnose", capture)
    cfg = tmp_path / "c.toml"
    cfg.write_text(CONFIG + "[fluid]\ndensity = 1.1\n")
    with pytest.raises(Stop):
        calib.diagnosis.command.run_diagnose("nrel5mw", str(data), str(tmp_path / "out"), str(cfg),
                                             printer=lambda s: None)
    np.testing.assert_allclose(seen["density"], 1.1, rtol=1e-12)


def test_diagnose_states_the_set_up_in_force(tmp_path, lift_data):
    """The tilt and precone of the embedded rotor, applied by default, are said with their origin in
    diagnosis.json and the report (the set-up that was silent on data from an axisymmetric rotor)."""
    text = CONFIG.replace("use_tilt = false", "use_tilt = false\ntilt = 0.0") + \
        'candidates = ["pitch_offset"]\nmax_effects = 1\n'
    code, out = _diagnose(tmp_path, lift_data, text)
    assert code == 0
    stated = {i["quantity"]: (i["value"],
                              i["origin"]) for i in json.loads((out / "diagnosis.json").read_text())["setup"]}
    assert stated["tilt"] == ("0 deg", "[model] tilt")
    assert stated["precone"] == ("2.5 deg", "embedded rotor 'nrel5mw'")
    assert stated["tilt in the BEM"] == ("ignored (use_tilt = false)", "[model] use_tilt")
    assert "Set-up in force" in (out / "report.html").read_text()
    assert "set-up in force: precone: 2.5 deg" in (out / "calib.log").read_text()


def test_a_failing_candidate_fit_leaves_the_others_compared(tmp_path, lift_data, monkeypatch):
    """One candidate whose fit raises is left out with a note; the round still names from the rest."""
    import calib.diagnosis.naming as D
    from calib.errors import ModelError

    real = D.Calibrator

    class FailsForPitch(real):
        def run(self):
            if self.name == "pitch_offset":
                raise ModelError("simulated solver failure")
            return super().run()

    monkeypatch.setattr(D, "Calibrator", FailsForPitch)
    code, out = _diagnose(tmp_path, lift_data, CONFIG + 'candidates = ["pitch_offset", "lift_offset"]\n'
                                                       'max_effects = 1\n')
    assert code == 0
    d = json.loads((out / "diagnosis.json").read_text())
    assert [c["name"] for c in d["rounds"][0]["candidates"]] == ["lift_offset"]
    assert any("candidate pitch_offset failed" in n and "simulated solver failure" in n for n in d["notes"])
    assert d["effect"] == "lift_offset" and not d["failure"]
