"""Unit mistakes caught before calibrating: synthetic NREL 5-MW tables written as CSV, then
corrupted the way field exports go wrong (right numbers, wrong unit in the header)."""

import json
from pathlib import Path

import numpy as np
import pytest

from calib.bem.solver import BemSettings
from calib.checks.unit_check import check_units
from calib.errors import InputError
from calib.measurements import Measurements, read_measurements, synthesize
from calib.models.base import Capabilities, Evaluation, OperatingConditions
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import Status, nominal_vector

CHANNELS = ("power", "thrust", "root_flap_moment")
# (header, SI column name): the table as a logger would write it, every unit stated
COLUMNS = (("wind_speed [m/s]", "wind_speed"), ("rotor_speed [rpm]", "rotor_speed"), ("pitch [deg]", "pitch"),
           ("power [W]", "power"), ("thrust [N]", "thrust"), ("root_flap_moment [N m]", "root_flap_moment"),
           ("power_sigma [W]", "power_sigma"), ("thrust_sigma [N]", "thrust_sigma"),
           ("root_flap_moment_sigma [N m]", "root_flap_moment_sigma"))


@pytest.fixture(scope="module")
def nrel():
    """A small NREL 5-MW BEM, its nominal vector and 10 field-like points with 2 % noise.

    The points follow the NREL 5-MW steady schedule (Jonkman et al. 2009, NREL/TP-500-38060,
    table 7-1): rotor speed λ-tracking between 6.9 and 12.1 rpm, pitch 0 below rated and
    3.8-22.4 deg above, so that every condition matters somewhere.
    """
    rotor = load_rotor("nrel5mw")
    model = BemModel(rotor, None, CHANNELS, BemSettings(use_tilt=False))
    p0 = nominal_vector(model.parameters)
    v = np.array([5.0, 7.0, 9.0, 10.5, 12.0, 14.0, 16.0, 18.0, 21.0, 24.0])
    rpm = np.clip(7.55 * v / rotor.rotor_radius * 30 / np.pi, 6.9, 12.1)
    pitch = np.interp(v, [11.4, 12, 14, 16, 18, 20, 22, 24], [0, 3.83, 8.7, 12.06, 14.92, 17.47, 19.94, 22.35])
    truth = synthesize(model, p0, OperatingConditions(v, rpm, pitch),
                       relative_sigma={c: 0.02 for c in CHANNELS}, seed=3)
    return model, p0, truth


def write_table(path: Path, meas: Measurements, numbers=None, headers=None) -> Path:
    """``meas`` as a CSV with units in the headers; ``numbers`` maps a column to a function of its SI
    values (what is written), ``headers`` a column to another header (what it is said to be)."""
    numbers, headers = numbers or {}, headers or {}
    cols = {"wind_speed": meas.conditions.wind_speed, "rotor_speed": meas.conditions.rotor_speed,
            "pitch": meas.conditions.pitch}
    for k, c in enumerate(meas.channels):
        cols[c], cols[f"{c}_sigma"] = meas.values[:, k], meas.sigma[:, k]
    lines = [",".join(headers.get(name, head) for head, name in COLUMNS)]
    data = [numbers.get(name, lambda x: x)(cols[name]) for _, name in COLUMNS]
    lines += [",".join(repr(float(x)) for x in row) for row in np.column_stack(data)]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_clean_table_passes(nrel, tmp_path):
    model, p0, truth = nrel
    meas = read_measurements(write_table(tmp_path / "clean.csv", truth))
    report = check_units(model, p0, meas)
    assert report.ok, report.summary()
    assert report.findings == ()
    for c in CHANNELS:
        assert abs(report.ratios[c] - 1) < 0.05, c
    report.raise_if_failed()                                   # nothing to raise
    assert json.loads(json.dumps(report.as_dict()))["ok"] is True


# numbers written as (SI value -> number in the file); the header keeps the SI unit
CORRUPTIONS = {
    "power in kW labelled W": ({"power": lambda w: w / 1e3, "power_sigma": lambda w: w / 1e3},
                               "channel", "power", 1e-3, "power looks like kW read as W"),
    "wind speed in km/h labelled m/s": ({"wind_speed": lambda v: v * 3.6},
                                        "condition", "wind_speed", 3.6, "wind_speed looks like km/h read as m/s"),
    "rotor speed in rad/s labelled rpm": ({"rotor_speed": lambda n: n * np.pi / 30},
                                          "condition", "rotor_speed", np.pi / 30,
                                          "rotor_speed looks like rad/s read as rpm"),
    "pitch in rad labelled deg": ({"pitch": np.radians},
                                  "condition", "pitch", np.pi / 180, "pitch looks like rad read as deg"),
}


@pytest.mark.parametrize("case", list(CORRUPTIONS))
def test_unit_mistake_stops_with_the_suspected_factor(nrel, tmp_path, case):
    model, p0, truth = nrel
    numbers, kind, name, factor, words = CORRUPTIONS[case]
    path = write_table(tmp_path / "field.csv", truth, numbers)
    report = check_units(model, p0, read_measurements(path))
    assert not report.ok
    assert [(f.kind, f.name) for f in report.findings] == [(kind, name)], report.summary()
    found = report.findings[0]
    assert found.factor == pytest.approx(factor, rel=1e-12)
    assert words in found.message
    with pytest.raises(InputError) as err:
        report.raise_if_failed()
    msg = str(err.value)
    assert str(path) in msg and err.value.field == name and f"{found.factor:.4g}" in msg
    assert "--force" in msg and "[calibration] force = true" in msg


def test_header_unit_is_used_to_name_the_mistake(nrel, tmp_path):
    """Numbers in W under a [kW] header: the words name both units and the header to write."""
    model, p0, truth = nrel
    path = write_table(tmp_path / "w_as_kw.csv", truth,
                       headers={"power": "power [kW]", "power_sigma": "power_sigma [kW]"})
    report = check_units(model, p0, read_measurements(path))
    assert [(f.kind, f.name) for f in report.findings] == [("channel", "power")]
    assert report.findings[0].factor == pytest.approx(1e3, rel=1e-12)
    assert "power looks like W read as kW" in report.findings[0].message
    assert "write the header as 'power [W]'" in report.findings[0].message


def test_polar_error_is_not_a_unit_mistake(nrel):
    """10 % less power than the nominal model (what calibration is for) passes the check, even with
    the tight noise of 10-minute means (1 %, so the plain χ²/dof of power is about 100)."""
    model, p0, truth = nrel
    values = truth.values.copy()
    values[:, 0] *= 0.90
    deficit = Measurements(truth.conditions, truth.channels, values, 0.01 * np.abs(values), source="deficit")
    report = check_units(model, p0, deficit)
    assert report.ok, report.summary()
    assert report.ratios["power"] == pytest.approx(0.90, abs=0.03)   # the deficit is seen, not blamed on units
    assert report.chi2_per_dof["power"] < report.chi2_threshold


def test_scattered_ratios_are_not_called_a_unit_factor(nrel):
    """A median ratio of 3.6 made of ratios from 1.8 to 7.2 is a misfit, not km/h ↔ m/s."""
    model, p0, truth = nrel
    values = truth.values.copy()
    values[:, 0] *= 3.6 * np.array([0.5, 2, 0.5, 2, 1, 1, 0.5, 2, 0.5, 2])
    report = check_units(model, p0, Measurements(truth.conditions, truth.channels, values, truth.sigma))
    assert report.ratios["power"] == pytest.approx(3.6, rel=0.1)
    assert [(f.kind, f.name) for f in report.findings] == [("misfit", "power")], report.summary()


def test_gross_misfit_without_a_unit_factor_is_a_finding(nrel):
    model, p0, truth = nrel
    values = truth.values.copy()
    values[:, 1] *= 2.0                                         # no unit factor is near 2
    report = check_units(model, p0, Measurements(truth.conditions, truth.channels, values, truth.sigma))
    assert [(f.kind, f.name) for f in report.findings] == [("misfit", "thrust")], report.summary()
    assert np.isnan(report.findings[0].factor)
    assert report.chi2_per_dof["thrust"] > report.chi2_threshold


def test_opposite_sign_is_a_finding(nrel):
    model, p0, truth = nrel
    values = truth.values.copy()
    values[:, 2] *= -1.0
    report = check_units(model, p0, Measurements(truth.conditions, truth.channels, values, truth.sigma))
    assert [(f.kind, f.name, f.factor) for f in report.findings] == [("sign", "root_flap_moment", -1.0)]


def test_unknown_noise_uses_a_relative_sigma_and_says_so(nrel):
    model, p0, truth = nrel
    blind = Measurements(truth.conditions, truth.channels, truth.values, None)
    report = check_units(model, p0, blind)
    assert report.ok, report.summary()
    assert any("5% of the model value" in n for n in report.notes)
    values = truth.values.copy()
    values[:, 0] /= 1e6                                         # MW read as W, no σ anywhere
    report = check_units(model, p0, Measurements(truth.conditions, truth.channels, values, None))
    assert [(f.kind, f.name) for f in report.findings] == [("channel", "power")]
    assert report.findings[0].factor == pytest.approx(1e-6)


def test_sigma_from_the_settings_replaces_the_relative_assumption(nrel):
    model, p0, truth = nrel
    blind = Measurements(truth.conditions, truth.channels, truth.values, None)
    report = check_units(model, p0, blind, sigma={"power": 5e4, "thrust": 1e4})
    assert report.ok, report.summary()
    assert "no σ for root_flap_moment: 5% of the model value used" in report.notes


class FailingAbove:
    """The NREL BEM, but every point above ``limit`` m/s reported as not converged."""

    def __init__(self, model, limit):
        self.model, self.limit = model, limit
        self.parameters, self.channels = model.parameters, model.channels
        self.capabilities = Capabilities("FailingAbove")

    def evaluate(self, p, conditions):
        ev = self.model.evaluate(p, conditions)
        bad = conditions.wind_speed > self.limit
        values, status = ev.values.copy(), ev.status.copy()
        values[bad], status[bad] = np.nan, Status.NOT_CONVERGED
        return Evaluation(values, status, tuple("stub" if b else "" for b in bad), ev.channels)


def test_model_failing_at_most_points_is_a_finding(nrel):
    model, p0, truth = nrel
    report = check_units(FailingAbove(model, 8.0), p0, truth)           # 8 of 10 points fail
    assert [f.kind for f in report.findings] == ["failures"], report.summary()
    assert "fails at 8 of 10 measured points" in report.findings[0].message
    assert report.n_failed == 8
    assert check_units(FailingAbove(model, 20.0), p0, truth).ok        # 2 of 10: not a unit matter


def test_a_condition_zero_everywhere_is_said_to_be_unchecked(nrel):
    model, p0, truth = nrel
    below = np.flatnonzero(truth.conditions.pitch == 0)
    sub = Measurements(truth.conditions.subset(below), truth.channels, truth.values[below], truth.sigma[below])
    report = check_units(model, p0, sub)
    assert report.ok
    assert "pitch is 0 at every point: a unit mistake in it cannot be seen" in report.notes
    assert not any(h.startswith("pitch") for h, _ in report.hypotheses)


# ----------------------------------------------------------------------------- the gate before a run
def pitch_offset_data(nrel, offset_deg: float = 3.0) -> Measurements:
    """The truth with a collective pitch offset: every load off by a ratio no unit factor explains."""
    model, p0, truth = nrel
    moved = OperatingConditions(truth.conditions.wind_speed, truth.conditions.rotor_speed,
                                truth.conditions.pitch + offset_deg)
    data = synthesize(model, p0, moved, relative_sigma={c: 0.01 for c in CHANNELS}, seed=5)
    return Measurements(truth.conditions, data.channels, data.values, data.sigma, source="offset.csv")


def test_misfit_no_unit_factor_explains_warns_and_goes_on(nrel):
    """A 3 deg pitch offset misfits beyond the threshold, but no unit factor explains it: the gate
    prints the ratio per channel and that no unit factor explains it, and does not stop."""
    from calib.checks.unit_check import apply_unit_check

    model, p0, _ = nrel
    meas = pitch_offset_data(nrel)
    lines = []
    report, notes = apply_unit_check(model, p0, meas, printer=lines.append, prefix="[test]")
    assert report.misfit_findings and not report.unit_findings, report.summary()
    warning, = [line for line in lines if "WARNING" in line]
    assert "no unit factor explains it" in warning and "calibrating anyway" in warning
    for c in CHANNELS:
        assert f"{c} {report.ratios[c]:.3g}" in warning
    assert all(line.startswith("[test] ") for line in lines)
    (key, text), = notes.items()
    assert "no unit factor explains" in key and text.startswith("measured/model per channel")
    with pytest.raises(InputError, match="--strict-units"):              # unless the user asks for strictness
        apply_unit_check(model, p0, meas, printer=lines.append, strict=True)


def test_unit_factor_still_stops_and_force_overrides(nrel, tmp_path):
    from calib.checks.unit_check import apply_unit_check

    model, p0, truth = nrel
    path = write_table(tmp_path / "kw.csv", truth, numbers={"power": lambda x: x / 1e3,
                                                            "power_sigma": lambda x: x / 1e3})
    meas = read_measurements(path)
    with pytest.raises(InputError, match="suspected factor 0.001") as err:
        apply_unit_check(model, p0, meas, printer=lambda s: None, source=str(path))
    assert str(path) in str(err.value) and err.value.field == "power"
    _, notes = apply_unit_check(model, p0, meas, printer=lambda s: None, force=True)
    assert list(notes) == ["unit check (overridden by force)"]


def test_fmu_units_name_the_mapping_as_a_cause(nrel, tmp_path):
    model, p0, truth = nrel
    path = write_table(tmp_path / "kw.csv", truth, numbers={"power": lambda x: x / 1e3,
                                                            "power_sigma": lambda x: x / 1e3})
    report = check_units(model, p0, read_measurements(path), model_units="the mapping file turbine.toml")
    assert "scale/unit mapped to 'power' in the mapping file turbine.toml" in report.findings[0].message
    assert "mapping" not in check_units(model, p0, read_measurements(path)).findings[0].message


def test_gross_ratio_no_factor_matches_still_stops(nrel):
    """kW read as W on data that are also 3 deg off in pitch: the power ratio (about 5e-4) matches no
    unit factor within tolerance, but no polar correction explains it either: it stops."""
    from calib.checks.unit_check import apply_unit_check
    from calib.checks.unit_findings import GROSS_RATIO

    model, p0, _ = nrel
    meas = pitch_offset_data(nrel)
    values, sigma = meas.values.copy(), meas.sigma.copy()
    values[:, 0] /= 1e3
    sigma[:, 0] /= 1e3
    both = Measurements(meas.conditions, meas.channels, values, sigma, source="both.csv")
    with pytest.raises(InputError, match="no calibration of the polars can either") as err:
        apply_unit_check(model, p0, both, printer=lambda s: None)
    assert err.value.field == "power" and "thrust" not in str(err.value)     # thrust: a misfit, not a stop
    report = check_units(model, p0, both)
    assert report.ratios["power"] < 1 / GROSS_RATIO
