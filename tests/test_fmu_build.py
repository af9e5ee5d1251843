"""Building, validating and running the rotor FMUs (variants A and B) and their mappings."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

import fmpy  # noqa: E402  (a core dependency: a missing install must fail, not skip)

from calib.fmu import build as fmu_build  # noqa: E402
from calib.fmu.build import FmuBuildError, build_fmu, mapping_path  # noqa: E402
from calib.fmu.resources import default_grid  # noqa: E402




@pytest.mark.parametrize("variant", ["A", "B"])
def test_fmpy_validate_passes(fmus, variant):
    from fmpy.validation import validate_fmu
    assert validate_fmu(str(fmus[variant])) == []


@pytest.mark.parametrize("variant", ["A", "B"])
def test_plain_fmpy_simulation(fmus, variant):
    res = fmpy.simulate_fmu(str(fmus[variant]), stop_time=10.0, output_interval=0.05)
    md = fmpy.read_model_description(str(fmus[variant]))
    assert md.fmiVersion == {"A": "2.0", "B": "3.0"}[variant]
    for name in res.dtype.names:
        assert np.all(np.isfinite(res[name])), name
    power = res["power" if variant == "A" else "Rotor.Power"]
    assert power.min() > 0
    assert np.ptp(power) > 0  # tower, shear, gravity and flexibility are on by default


def test_build_is_cached(fmus, tmp_path):
    path = fmus["A"]
    mtime = path.stat().st_mtime_ns
    assert build_fmu("A") == path and path.stat().st_mtime_ns == mtime
    copy = build_fmu("A", out_dir=tmp_path)
    assert copy.is_file() and (tmp_path / "calib_rotor_a.mapping.toml").is_file()


def test_no_binaries_or_sources_in_repository():
    tracked = list(fmu_build.FMU_MODELS.rglob("*.so")) + list(fmu_build.FMU_MODELS.rglob("*.fmu"))
    assert tracked == []


def test_missing_compiler_or_cmake_says_what_to_install(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    with pytest.raises(FmuBuildError) as info:
        build_fmu("A", force=True)
    msg = str(info.value)
    assert "CMake" in msg and "C compiler" in msg and "apt-get install" in msg


def test_unknown_variant_is_named():
    with pytest.raises(ValueError, match="valid: A, B"):
        build_fmu("C")


@pytest.mark.parametrize("variant", ["A", "B"])
def test_mapping_names_exist_with_right_causality(fmus, variant):
    with open(mapping_path(variant), "rb") as fh:
        m = tomllib.load(fh)
    md = fmpy.read_model_description(str(fmus[variant]))
    vars_ = {v.name: v for v in md.modelVariables}
    assert m["fmi_version"] == md.fmiVersion
    for name, e in m["inputs"].items():
        assert vars_[e["variable"]].causality == "input", name
    for name, e in m["outputs"].items():
        for v in e.get("variables", [e.get("variable")]):
            assert vars_[v].causality == "output", name
    for table in ("switches", "settings", "parameters"):
        for name, e in m[table].items():
            assert vars_[e["variable"]].causality == "parameter", name
    grid = default_grid()
    c = m["corrections"]
    if c["layout"] == "scalar":
        names = [c[b].format(i=i, j=j) for b in ("lift", "drag") for i in range(grid.n_alpha)
                 for j in range(grid.n_eta)]
    else:
        names = [c["lift"], c["drag"]]
        assert all(int(vars_[n].dimensions[0].start) == grid.n_lift for n in names)
    assert all(vars_[n].variability == "tunable" for n in names)


def test_variants_agree_after_mapping(fmus):
    """Same physics behind both vendor interfaces: with only what the mapping files say (their
    [settings] values override the vendors' different defaults -- shear exponent 0.14 vs 0.2,
    damping ratios 0.5 % vs 1 %), mapped to package units, A and B agree; flexible blades,
    shear, tower shadow and gravity are on (the vendors' defaults)."""
    def start(variant, wind, rpm):
        with open(mapping_path(variant), "rb") as fh:
            m = tomllib.load(fh)
        values = {e["variable"]: (e.get("sign", 1) * e["value"] - e.get("offset", 0.0)) / e.get("scale", 1.0)
                  for e in m["settings"].values() if "value" in e}
        for name, x in (("wind_speed", wind), ("rotor_speed", rpm)):
            e = m["inputs"][name]
            values[e["variable"]] = x / e.get("scale", 1.0)
        return values

    common = dict(stop_time=6.0, output_interval=0.1)
    a = fmpy.simulate_fmu(str(fmus["A"]), start_values=start("A", 9.0, 10.0), **common)
    b = fmpy.simulate_fmu(str(fmus["B"]), start_values=start("B", 9.0, 10.0), **common)
    assert np.ptp(a["tip_flap_deflection_blade1"]) > 0.01   # the structure moves: damping matters
    np.testing.assert_allclose(b["Rotor.Power"] * 1e3, a["power"], rtol=1e-9)
    np.testing.assert_allclose(b["Blade.RootMyFlap"][:, 1] * 1e3, a["root_flap_moment_blade2"], rtol=1e-9)
    np.testing.assert_allclose(-b["Blade.RootMxEdge"][:, 0] * 1e3, a["root_edge_moment_blade1"], rtol=1e-9)
    np.testing.assert_allclose(np.mod(b["Rotor.Azimuth"] - 180.0, 360.0), a["azimuth"], atol=1e-9)


@pytest.mark.parametrize("variant", ["A", "B"])
def test_log_categories_declared_and_honoured(fmus, variant):
    """The model description lists the log categories; fmi*SetDebugLogging accepts each,
    refuses an unknown one (with a message), and switching a category off silences it."""
    from fmpy.fmi1 import FMICallException
    from test_fmu_inputs import NAMES, Fmu
    md = fmpy.read_model_description(str(fmus[variant]))
    names = [c.name for c in md.logCategories]
    assert names == ["logEvents", "logStatusWarning", "logStatusError"]
    f = Fmu(fmus[variant], variant)
    try:
        f.slave.setDebugLogging(True, names)
        with pytest.raises(FMICallException):
            f.slave.setDebugLogging(True, ["logEverything"])
        assert "unknown log category 'logEverything'" in f.errors()
        f.initialize()
        assert any(c == "logEvents" and "initialized" in m for _, c, m in f.messages)
        f.slave.setDebugLogging(False, ["logStatusError"])
        f.messages.clear()
        with pytest.raises(FMICallException):      # still refused, but silently
            f.set(**{NAMES[variant]["rotor_speed"]: -1.0})
        assert f.messages == []
        f.slave.setDebugLogging(True, [])            # no categories: all on
        with pytest.raises(FMICallException):
            f.set(**{NAMES[variant]["rotor_speed"]: -1.0})
        assert [c for _, c, _ in f.messages] == ["logStatusError"]
    finally:
        f.slave.freeInstance()


def test_bad_input_is_an_error_not_a_nan(fmus):
    with pytest.raises(Exception, match="fmi2DoStep|Error|failed"):
        fmpy.simulate_fmu(str(fmus["A"]), stop_time=1.0, start_values={"air_density": -1.0})


def test_fmu_state_round_trip(fmus):
    """Save/restore of the FMU state reproduces a continuation exactly (FMI 2 and 3)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    path = str(fmus["A"])
    md = read_model_description(path)
    unzip = extract(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    for k in range(20):
        fmu.doStep(k * 0.05, 0.05)
    state = fmu.getFMUstate()
    for k in range(20, 40):
        fmu.doStep(k * 0.05, 0.05)
    first = fmu.getReal([vr["root_flap_moment_blade1"], vr["power"]])
    fmu.setFMUstate(state)
    for k in range(20, 40):
        fmu.doStep(k * 0.05, 0.05)
    assert fmu.getReal([vr["root_flap_moment_blade1"], vr["power"]]) == first
    fmu.freeFMUstate(state)
    fmu.terminate()
    fmu.freeInstance()


def test_spec_ranges_are_required_and_checked(tmp_path):
    """variables.toml: inputs and Real/Integer parameters need min <= start <= max (they become
    the model description's range and the FMU's refusal rule); outputs and Booleans take none."""
    from calib.errors import InputError
    from calib.fmu import model_description as md
    from calib.fmu import variant_spec
    ids = variant_spec.core_variable_ids(fmu_build.CORE_DIR / "rotor_core.h")
    kw = dict(n_nodes=1, alpha_nodes=[0.0], eta_nodes=[1.0], out_radius=[], out_eta=[], rotor_facts={})
    head = '[fmu]\nfmi_version = "2.0"\nmodel_identifier = "x"\nmodel_name = "x"\nwrapper = "w.c"\n'
    cases = {
        'name = "v"\ncore = "WIND_SPEED"\nkind = "input"\nstart = 8.0\n': "min",
        'name = "v"\ncore = "WIND_SPEED"\nkind = "input"\nstart = 8.0\nmin = 9.0\nmax = 50.0\n': "start",
        'name = "v"\ncore = "WIND_SPEED"\nkind = "input"\nstart = 8.0\nmin = 60.0\nmax = 50.0\n': "min",
        'name = "v"\ncore = "POWER"\nkind = "output"\nmin = 0.0\nmax = 1.0\n': "min",
        'name = "v"\ncore = "N_BLADES"\nkind = "fixed"\ntype = "Integer"\nstart = 3\nmin = 2.5\nmax = 3\n': "min",
    }
    for body, field in cases.items():
        path = tmp_path / "v.toml"
        path.write_text(head + "[[variable]]\n" + body)
        with pytest.raises(InputError) as info:
            variant_spec.load_spec(path, ids, **kw)
        assert info.value.field == field, body
    path.write_text(head + "[[variable]]\n" + 'name = "v"\ncore = "WIND_SPEED"\nkind = "input"\nstart = 8.0\n'
                    'min = 0.0\nmax = 50.0\n')
    spec = variant_spec.load_spec(path, ids, **kw)
    assert (spec.variables[0].min, spec.variables[0].max) == (0.0, 50.0)
    assert 'min="0.0" max="50.0"' in md.render_fmi2(spec, "{g}")
