"""The FMU adapter (calib.fmu.model.FmuModel): load-time checks with messages naming file
and item, steady values and harmonics, fault survival, settled states, specs, workflow tables.

The bundled rotor FMUs are built with a small correction grid and driven with quasi-steady
physics (rigid blades, no dynamic inflow, no tower, shear or yaw) and a coarse window, so that a
simulation costs milliseconds; the native BEM with the same settings is the reference.
"""

from __future__ import annotations

import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from calib.bem import BemSettings
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.fmu.build import build_fmu, mapping_path
from calib.fmu.model import FmuModel
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions, Status

GRID = CorrectionGrid([0.0, 5.0, 10.0], [0.4, 0.9])
QUIET = dict(tower_shadow=False, shear=False, yaw=False, flexible_blades=False, gravity=False, dynamic_inflow=False,
             stall_delay=False, skewed_wake=False, tip_loss=True, hub_loss=True)
FAST = {"shaft_tilt": 0.0, "max_internal_step": 0.1, "max_azimuth_step": 10.0}
WINDOW = dict(steps_per_revolution=8, settle_revolutions=0, average_revolutions=2, perturbation_settle_revolutions=0,
              perturbation_average_revolutions=1)
CHANNELS = ["power", "thrust", "root_flap_moment"]
BEM_SETTINGS = BemSettings(tip_loss=True, hub_loss=True, n_sectors=1, shear_exponent=0.0, use_tilt=False)


@pytest.fixture(scope="module")
def rotor():
    return load_rotor("nrel5mw")


@pytest.fixture(scope="module")
def small_fmus(rotor):
    return {v: build_fmu(v, rotor, GRID) for v in "AB"}


def quick_model(path, variant, **kw):
    opts = dict(channels=CHANNELS, parameters=[], switches=QUIET, settings=FAST, steady=WINDOW,
                jacobian=dict(warm_start=True))      # quasi-steady: a restored state has no lag
    opts.update(kw)
    return FmuModel(path, mapping_path(variant), **opts)


def conditions(rotor, tsr=(6.0, 7.5, 9.0, 10.5), pitch=(0.0, 3.0), rpm=10.0):
    T, P = np.meshgrid(np.asarray(tsr), np.asarray(pitch), indexing="ij")
    v = rpm * np.pi / 30 * rotor.rotor_radius / T.ravel()
    return OperatingConditions(v, np.full(v.size, rpm), P.ravel())


def edited_mapping(tmp_path, variant, old, new, name="mapping.toml"):
    text = mapping_path(variant).read_text()
    assert old in text
    path = tmp_path / name
    path.write_text(text.replace(old, new, 1))
    return path


# ------------------------------------------------------------------ bad input
def test_not_a_zip_is_refused(tmp_path):
    bad = tmp_path / "turbine.fmu"
    bad.write_text("modelDescription.xml is not here, this is text")
    with pytest.raises(InputError, match="not a zip archive") as err:
        FmuModel(bad, mapping_path("A"))
    assert str(bad) in str(err.value)


def test_zip_entry_escaping_the_folder_is_refused(tmp_path, small_fmus):
    evil = tmp_path / "evil.fmu"
    shutil.copy(small_fmus["A"], evil)
    with zipfile.ZipFile(evil, "a") as z:
        z.writestr("resources/../../outside.txt", "escape")
    with pytest.raises(InputError, match="outside the extraction folder") as err:
        FmuModel(evil, mapping_path("A"))
    assert err.value.field == "resources/../../outside.txt" and str(evil) in str(err.value)
    assert not (tmp_path / "outside.txt").exists()


def test_fmu_without_binary_for_this_platform_is_refused(tmp_path, small_fmus):
    src, dst = small_fmus["A"], tmp_path / "windows_only.fmu"
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            name = info.filename.replace("binaries/linux64/", "binaries/win64/").replace(".so", ".dll")
            zout.writestr(name, zin.read(info))
    with pytest.raises(InputError, match="no binary for this platform") as err:
        FmuModel(dst, mapping_path("A"))
    assert err.value.field == "binaries/linux64/calib_rotor_a.so" and "win64" in str(err.value)


def test_mapped_variable_that_does_not_exist_is_refused(tmp_path, small_fmus):
    mapping = edited_mapping(tmp_path, "A", 'thrust = { variable = "thrust"', 'thrust = { variable = "thrust_total"')
    with pytest.raises(InputError, match="'thrust_total' does not exist") as err:
        FmuModel(small_fmus["A"], mapping)
    assert err.value.field == "outputs.thrust" and str(mapping) in str(err.value) and "'thrust'" in str(err.value)


def test_parameter_that_is_not_tunable_is_refused(tmp_path, small_fmus):
    mapping = edited_mapping(tmp_path, "B", "[parameters]\n",
                             '[parameters]\nblade_mass = { variable = "Struct.BladeMass", unit = "t", scale = 1.0 }\n')
    with pytest.raises(InputError, match="'Struct.BladeMass' is not tunable") as err:
        FmuModel(small_fmus["B"], mapping)
    assert err.value.field == "parameters.blade_mass" and str(mapping) in str(err.value)


@pytest.mark.parametrize("old,new,field", [
    ("[steady]\n", "[steady]\nsettle_time = 3.0\n", "steady.settle_time"),
    ('schema = "calib.fmu.mapping/1"\n', 'schema = "calib.fmu.mapping/1"\nvendor = "x"\n', "vendor"),
    ('power = { variable = "power", unit = "W" }', 'power = { variable = "power", unit = "W", gain = 2 }',
     "outputs.power.gain"),
])
def test_mapping_with_an_unknown_key_is_refused(tmp_path, old, new, field):
    from calib.fmu.mapping import load_mapping
    mapping = edited_mapping(tmp_path, "A", old, new)
    with pytest.raises(InputError, match="unknown key") as err:
        load_mapping(mapping)
    assert err.value.field == field and str(mapping) in str(err.value)


def test_state_from_another_build_is_refused(tmp_path, small_fmus, rotor):
    """Settled states carry the build's GUID: variant B refuses A's; A restores its own and, the
    physics being steady, evaluates to the cold result."""
    cond = conditions(rotor, tsr=(7.5,), pitch=(0.0,))
    a, b = quick_model(small_fmus["A"], "A"), quick_model(small_fmus["B"], "B")
    p = np.zeros(len(a.parameters))
    states = a.settled_states(p, cond)
    path = a.save_states(tmp_path / "settled.states", states, cond)
    with pytest.raises(InputError, match="state from another build") as err:
        b.load_states(path)
    assert err.value.field == "guid" and str(path) in str(err.value) and a.guid in str(err.value)
    loaded, cond2 = a.load_states(path)
    warm = a.evaluate(p, cond2, start_states=loaded)
    cold = a.evaluate(p, cond)
    assert np.all(warm.status == 0)
    np.testing.assert_allclose(warm.values, cold.values, rtol=1e-9)
    a.close()
    b.close()


# ------------------------------------------------------------------ values, harmonics, Jacobian
def test_steady_values_and_jacobian_match_the_native_bem(small_fmus, rotor):
    """Quasi-steady FMU and native BEM share polars, kinematics and element solver: values agree to
    1e-4 and the warm-started central differences to 1 % of the largest sensitivity of each channel
    (the BEM's are exact); both variants give the same numbers through their own mappings."""
    cond = conditions(rotor, tsr=(6.0, 9.0), pitch=(0.0, 3.0))
    bem = BemModel(rotor, GRID, CHANNELS, BEM_SETTINGS, nuisance=())
    rng = np.random.default_rng(3)
    p = np.concatenate([0.05 * rng.standard_normal(GRID.n_lift), 0.003 * rng.standard_normal(GRID.n_lift)])
    ev_ref, G_ref = bem.jacobian(p, cond)
    out = {}
    for v in "AB":
        m = quick_model(small_fmus[v], v)
        assert [q.name for q in m.parameters] == [q.name for q in bem.parameters]
        ev, G = m.jacobian(p, cond)
        assert np.all(ev.status == Status.CONVERGED), ev.messages
        np.testing.assert_allclose(ev.values, ev_ref.values, rtol=1e-4)
        scale = np.abs(G_ref).max(axis=(0, 2))[None, :, None]
        assert np.max(np.abs(G - G_ref) / scale) < 0.01
        out[v] = (ev.values, G)
        m.close()
    np.testing.assert_allclose(out["A"][0], out["B"][0], rtol=1e-10)
    np.testing.assert_allclose(out["A"][1], out["B"][1], rtol=1e-6, atol=1e-9 * np.abs(out["A"][1]).max())


def test_the_drag_floor_holds_in_the_fmu_as_in_the_native_bem(small_fmus, rotor):
    """Drag nodes far below C_D = 0: both models hold the corrected drag at min(0.001, C_D,0) at
    every element, evaluate every point and agree as they do without the floor."""
    cond = conditions(rotor, tsr=(6.0, 9.0), pitch=(0.0, 3.0))
    bem = BemModel(rotor, GRID, CHANNELS, BEM_SETTINGS, nuisance=())
    p = np.concatenate([np.zeros(GRID.n_lift), np.full(GRID.n_lift, -0.15)])
    ref = bem.evaluate(p, cond)
    assert np.all(ref.status == Status.CONVERGED), ref.messages
    m = quick_model(small_fmus["A"], "A")
    ev = m.evaluate(p, cond)
    m.close()
    assert np.all(ev.status == Status.CONVERGED), ev.messages
    np.testing.assert_allclose(ev.values, ref.values, rtol=1e-4)


def test_harmonic_channels_show_shear_and_tower(small_fmus):
    """Shear makes blade 1's flap moment peak at the top (1P phase near 0 deg); three identical
    blades pass the tower three times a revolution, so thrust carries 3P and no 1P."""
    chans = ["root_flap_moment", "root_flap_moment_1p", "root_flap_moment_1p_phase", "thrust_1p", "thrust_3p",
             "thrust"]
    cond = OperatingConditions([10.0], [11.4], [0.0])
    steady = dict(steps_per_revolution=36, settle_revolutions=1, average_revolutions=2)
    quiet = quick_model(small_fmus["A"], "A", channels=chans, steady=steady, corrections=False)
    windy = quick_model(small_fmus["A"], "A", channels=chans, steady=steady, corrections=False,
                        switches=dict(QUIET, shear=True, tower_shadow=True), settings=dict(FAST, shear_exponent=0.2))
    assert [c.unit for c in windy.channels][1:3] == ["N m", "deg"]
    q = dict(zip(chans, quiet.evaluate([], cond).values[0]))
    w = dict(zip(chans, windy.evaluate([], cond).values[0]))
    assert q["root_flap_moment_1p"] < 1e-6 * q["root_flap_moment"]
    assert w["root_flap_moment_1p"] > 0.02 * w["root_flap_moment"]
    assert abs(w["root_flap_moment_1p_phase"]) < 30.0
    assert w["thrust_3p"] > 1e-3 * w["thrust"] and w["thrust_1p"] < 0.1 * w["thrust_3p"]
    quiet.close()
    windy.close()


# ------------------------------------------------------------------ faults
@pytest.mark.parametrize("fault,status,text", [
    (1, Status.SIMULATION_FAILED, "debug_fault = 1"),
    (2, Status.SIMULATION_FAILED, "SIGABRT"),
    (3, Status.TIMEOUT, "timeout"),
])
def test_faults_are_statuses_and_nothing_else_is_lost(small_fmus, rotor, fault, status, text):
    """The FMU returns an error, aborts the process, or hangs at the points above 9 m/s: those
    points get the status and a message, the worker is rebuilt, and every other point keeps the
    value of a fault-free run."""
    cond = conditions(rotor, tsr=(6.0, 9.0, 12.0), pitch=(0.0,), rpm=12.0)
    assert np.any(cond.wind_speed > 9.0) and np.any(cond.wind_speed <= 9.0)
    clean = quick_model(small_fmus["A"], "A").evaluate(np.zeros(GRID.n_params), cond)
    m = quick_model(small_fmus["A"], "A", settings=dict(FAST, debug_fault=fault, debug_fault_wind_speed=9.0),
                    timeout=3.0)
    ev = m.evaluate(np.zeros(GRID.n_params), cond)
    hit = cond.wind_speed > 9.0
    assert np.all(ev.status[hit] == status) and all(text in msg for msg, h in zip(ev.messages, hit) if h)
    assert np.all(ev.status[~hit] == 0)
    np.testing.assert_array_equal(ev.values[~hit], clean.values[~hit])
    assert np.all(np.isnan(ev.values[hit]))
    if fault > 1:
        assert ev.extras["restarts"][hit].sum() >= 1
    m.close()


def test_calibration_finishes_past_a_crashing_point(small_fmus, rotor):
    """A calibration whose FMU crashes at one operating point finishes; the point is counted as
    failed before and after, the others give the estimate."""
    from calib.calibration import calibrate
    from calib.measurements import synthesize

    cond = conditions(rotor, tsr=(6.0, 7.5, 9.0, 12.0), pitch=(0.0, 2.0), rpm=12.0)
    truth = quick_model(small_fmus["A"], "A", parameters=["pitch_offset_blade1"], corrections=False)
    p_true = np.array([0.8])
    meas = synthesize(truth, p_true, cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=4)
    winds = np.unique(cond.wind_speed)
    threshold = float(0.5 * (winds[-1] + winds[-2]))        # the highest wind speed (both pitches) crashes
    m = quick_model(small_fmus["A"], "A", parameters=["pitch_offset_blade1"], corrections=False,
                    settings=dict(FAST, debug_fault=2, debug_fault_wind_speed=threshold))
    res = calibrate(m, meas, retain="all", cd_min=None)
    crashed = cond.wind_speed > threshold
    assert crashed.sum() == 2
    assert np.all(res.fit.status_after[crashed] == Status.SIMULATION_FAILED) and np.all(res.fit.status_after[~crashed] == 0)
    assert np.all(res.fit.status_before[crashed] == Status.SIMULATION_FAILED)
    assert res.fit.failures["final"] == 2 and res.estimate.status == "converged"
    v = res.identifiability.verdicts[0]
    assert abs(v["value"] - p_true[0]) < 3 * v["std"]
    truth.close()
    m.close()


# ------------------------------------------------------------------ specs and workflow tables
def test_spec_rebuilds_the_model(small_fmus, rotor):
    from calib.models.registry import build_model
    m = quick_model(small_fmus["B"], "B", parameters=["stall_delay_strength"])
    m2 = build_model(m.spec())
    assert [q.name for q in m2.parameters] == [q.name for q in m.parameters]
    assert [c.name for c in m2.channels] == CHANNELS and m2.rotor_radius == pytest.approx(rotor.tip_radius)
    cond = conditions(rotor, tsr=(8.0,), pitch=(1.0,))
    p = np.array([q.nominal for q in m.parameters])
    np.testing.assert_array_equal(m.evaluate(p, cond).values, m2.evaluate(p, cond).values)
    m.close()
    m2.close()


def test_model_and_executor_from_workflow_tables(tmp_path, small_fmus):
    from calib.executors import ProcessExecutor, SerialExecutor
    from calib.models.from_config import executor_from_table, model_from_workflow

    src = str(tmp_path / "workflow.toml")
    table = {"kind": "fmu", "variant": "b", "switches": QUIET, "settings": FAST, "steady": WINDOW, "parameters": []}
    m = model_from_workflow(table, {"name": "nrel5mw"}, ["power"], src, tmp_path, grid=GRID)
    assert isinstance(m, FmuModel) and m.fmu_path == Path(small_fmus["B"]).resolve()
    assert m.spec()["build"]["variant"] == "B" and len(m.parameters) == GRID.n_params
    m.close()
    copied = tmp_path / "vendor.fmu"
    shutil.copy(small_fmus["A"], copied)
    shutil.copy(mapping_path("A"), tmp_path / "vendor.toml")
    m = model_from_workflow({"kind": "fmu", "fmu": "vendor.fmu", "mapping": "vendor.toml", "corrections": False},
                            {"name": "nrel5mw"}, ["thrust"], src, tmp_path)
    assert len(m.parameters) == 4 and m.channels[0].name == "thrust"
    m.close()
    for bad, field in (({"kind": "fmu", "fmu": "vendor.fmu"}, "model.mapping"),
                       ({"kind": "fmu", "fmu": "vendor.fmu", "mapping": "vendor.toml", "gain": 1}, "model.gain"),
                       ({"kind": "fmu"}, "model.fmu"), ({"kind": "modelica"}, "model.kind")):
        with pytest.raises(InputError) as err:
            model_from_workflow(bad, {"name": "nrel5mw"}, ["power"], src, tmp_path)
        assert err.value.field == field and src in str(err.value)
    assert isinstance(executor_from_table(None, src), SerialExecutor)
    ex = executor_from_table({"kind": "process", "workers": 2}, src)
    assert isinstance(ex, ProcessExecutor) and ex.workers == 2
    for bad, field in (({"kind": "mpi"}, "executor.kind"), ({"kind": "process", "address": "tcp://x:1"},
                                                             "executor.address"), ({"threads": 2}, "executor.threads")):
        with pytest.raises(InputError) as err:
            executor_from_table(bad, src)
        assert err.value.field == field and src in str(err.value)


def test_measured_harmonic_columns_are_channels(tmp_path):
    """The measured counterpart of the harmonic channels: more columns of the same CSV, converted
    to SI like their base channel (kN m -> N m), phases in degrees."""
    from calib.measurements import read_measurements
    csv = tmp_path / "loads.csv"
    csv.write_text("wind_speed [m/s],rotor_speed [rpm],pitch [deg],root_flap_moment_1p [kN m],"
                   "root_flap_moment_1p_phase [deg],thrust_3p [kN],root_edge_moment_blade2 [kNm]\n"
                   "10,11.4,0,812.5,-4.0,2.5,1500\n11,11.8,0,830.0,-3.5,2.7,1600\n")
    meas = read_measurements(csv)
    assert meas.channels == ("root_flap_moment_1p", "root_flap_moment_1p_phase", "thrust_3p",
                             "root_edge_moment_blade2")
    np.testing.assert_allclose(meas.values[0], [812.5e3, -4.0, 2.5e3, 1.5e6])


@pytest.mark.parametrize("fault,status,text", [(1, Status.SIMULATION_FAILED, "debug_fault = 1"),
                                               (2, Status.SIMULATION_FAILED, "died"), (3, Status.TIMEOUT, "timeout")])
def test_fault_in_a_perturbed_run_keeps_the_others(small_fmus, rotor, fault, status, text):
    """An error, a crash or a hang in the middle of a point's perturbed runs: that run gets the
    status; after an error the instance, after a crash or hang the worker process, is rebuilt
    and the remaining runs resume from the serialized settled base state; and
    every other run equals the fault-free one (nothing computed before is lost, nothing after is
    skipped). The fault is provoked by a perturbed run that also raises the wind speed input above
    the debug threshold."""
    import dataclasses

    from calib.fmu import worker as fw
    from calib.fmu.simulator import Simulator

    cond = OperatingConditions([8.0], [10.0], [0.0])
    p = np.zeros(GRID.n_params)
    clean = quick_model(small_fmus["A"], "A")
    faulty = quick_model(small_fmus["A"], "A", settings=dict(FAST, debug_fault=fault, debug_fault_wind_speed=9.0))
    _, [task_clean], _ = clean._tasks(p, cond, perturb=True)
    _, [task], _ = faulty._tasks(p, cond, perturb=True)
    windy = faulty._fmu_inputs(OperatingConditions([12.0], [10.0], [0.0]))[0]
    runs = list(task.perturbations)
    runs[5] = runs[5] + windy                       # the 6th perturbed run sets wind 12 m/s: fault
    task = dataclasses.replace(task, perturbations=tuple(runs))
    ref = Simulator(clean._plan).run_point(task_clean)
    worker = fw.WorkerProcess(faulty._plan, timeout=3.0)
    try:
        res = worker.run_point(task)
    finally:
        worker.close()
    assert res.base.ok and res.restarts == (0 if fault == 1 else 1) and res.base_state is not None
    assert res.perturbations[5].status == status and text in res.perturbations[5].message
    for j, (a, b) in enumerate(zip(res.perturbations, ref.perturbations)):
        if j != 5:
            assert a.ok, (j, a.message)
            np.testing.assert_array_equal(a.mean, b.mean)
    clean.close()
    faulty.close()


def test_forward_differences_agree_with_central_at_half_the_runs(small_fmus, rotor):
    """``jacobian = {differences = "forward"}`` (issue 38): one perturbed run per parameter against the base
    run; the sensitivities agree with central ones to the O(h) term, and an unknown scheme is refused
    naming the valid ones."""
    cond = conditions(rotor, tsr=(6.0, 9.0), pitch=(0.0,))
    names = ["pitch_offset_blade1", "stall_delay_strength"]
    central = quick_model(small_fmus["A"], "A", parameters=names, corrections=False,
                          jacobian=dict(differences="central", relative_step=0.01))
    forward = quick_model(small_fmus["A"], "A", parameters=names, corrections=False,
                          jacobian=dict(warm_start=True, differences="forward", relative_step=0.01))
    p = np.array([q.nominal for q in central.parameters])
    ev_c, G_c = central.jacobian(p, cond)
    ev_f, G_f = forward.jacobian(p, cond)
    np.testing.assert_array_equal(ev_f.values, ev_c.values)
    assert np.all(np.isfinite(G_f)) and np.abs(G_c).max() > 0
    np.testing.assert_allclose(G_f, G_c, rtol=0, atol=0.02 * np.abs(G_c).max())
    n = len(cond)
    assert central.simulation_summary()["simulations"] == n * (1 + 2 * len(names))
    assert forward.simulation_summary()["simulations"] == n * (1 + len(names))
    assert forward.jacobian_method.startswith("forward differences")
    with pytest.raises(InputError, match="central, forward"):
        quick_model(small_fmus["A"], "A", parameters=names, corrections=False, jacobian=dict(differences="backward"))
    central.close()
    forward.close()


def test_the_bundled_mappings_and_the_rule_default_to_forward_differences_at_a_tenth_of_the_scale():
    """The difference default (issue 38): forward at relative step 0.1, in both bundled mappings and for a
    mapping without ``[jacobian]`` (a step of 0.01 scale measured the bundled FMU's output jumps)."""
    import tomllib

    from calib.fmu.build import mapping_path
    from calib.fmu.rules import JacobianRule, jacobian_rule
    assert (JacobianRule().differences, JacobianRule().relative_step) == ("forward", 0.1)
    assert jacobian_rule({}, "none.toml").differences == "forward"
    for variant in ("A", "B"):
        data = tomllib.loads(mapping_path(variant).read_text())
        rule = jacobian_rule(data, str(mapping_path(variant)))
        assert (rule.differences, rule.relative_step) == ("forward", 0.1), variant
