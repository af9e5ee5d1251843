"""History and resume (calib.history): a run killed with SIGKILL part-way and resumed with
``--resume`` reaches the uninterrupted run's result without computing again what it had
computed; no file under a final name is ever half-written; a changed input is refused."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from calib.errors import InputError
from calib.history import count_model_calls, open_history, read_events

ROOT = Path(__file__).resolve().parents[1]
WORKFLOW = ROOT / "workflows" / "wind_tunnel_hub_loads.toml"


def small_workflow(tmp_path: Path) -> Path:
    """The wind-tunnel workflow on 24 operating points (one stage, ~15 Jacobians of 0.1 s)."""
    text = WORKFLOW.read_text()
    lines = []
    for line in text.splitlines():
        if line.startswith("tsr = "):
            line = "tsr = [2.0, 3.0, 4.0, 5.0, 6.0, 7.0]"
        elif line.startswith("pitch = "):
            line = "pitch = [-2.0, 1.0, 4.0, 7.0]"
        lines.append(line)
    path = tmp_path / "small.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def calib_cmd(*args) -> list[str]:
    return [sys.executable, "-m", "calib.cli", *map(str, args)]


def start(args, cwd) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen(calib_cmd(*args), cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def finish(proc: subprocess.Popen, timeout: float = 300) -> str:
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{out[-2000:]}\n{err[-4000:]}"
    return out


def kill_after(proc: subprocess.Popen, out_dir: Path, n_records: int, timeout: float = 240) -> int:
    """SIGKILL ``proc`` as soon as its history holds ``n_records`` computed model calls."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"the run ended (exit {proc.returncode}) before it had {n_records} records:\n"
                        f"{proc.stderr.read()[-3000:]}")
        if count_model_calls(read_events(out_dir))["computed"] >= n_records:
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=30)
            return count_model_calls(read_events(out_dir))["computed"]
        time.sleep(0.005)
    proc.kill()
    pytest.fail(f"no {n_records} records within {timeout} s")


def assert_complete_files(folder: Path) -> int:
    """Every file under a final name in ``folder`` parses completely; returns how many were checked.

    Temporary files (hidden, ``.tmp``) may remain after a SIGKILL: they are not final names.
    """
    from PIL import Image

    checked = 0
    for path in sorted(folder.rglob("*")):
        if not path.is_file() or path.name.startswith(".") or path.name.endswith(".tmp"):
            continue
        suffix = path.suffix
        if suffix == ".json":
            json.loads(path.read_text())
        elif suffix == ".npz":
            with np.load(path) as z:
                for key in z.files:
                    z[key]
            with zipfile.ZipFile(path) as zf:
                assert zf.testzip() is None, path
        elif suffix == ".jsonl":
            raw = path.read_text()
            assert raw == "" or raw.endswith("\n"), f"{path}: last line incomplete"
            for line in raw.splitlines():
                json.loads(line)
        elif suffix == ".png":
            with Image.open(path) as im:
                im.load()
        elif suffix == ".svg":
            import xml.etree.ElementTree as ET
            ET.parse(path)
        elif suffix == ".html":
            assert path.read_text().rstrip().endswith("</html>"), path
        elif suffix == ".csv":
            from calib.measurements import read_measurements
            read_measurements(path)
        elif suffix == ".log":
            continue        # appended text, no structure to complete
        else:
            pytest.fail(f"unexpected file {path}")
        checked += 1
    return checked


def test_killed_calibration_resumes_to_the_uninterrupted_result(tmp_path, capsys):
    """``calib run`` killed (SIGKILL) after 6 model calls, then ``calib run --resume DIR``.

    The uninterrupted reference run is ``calib run --verbose``: it also checks (to save a run)
    what ``--verbose`` prints and what ``calib.log`` keeps (tests/test_logging.py has the rest).
    """
    from calib.cli import main

    wf = small_workflow(tmp_path)
    full_dir, cut_dir = tmp_path / "full", tmp_path / "cut"
    cut = start(["run", wf, "--out", cut_dir, "--quiet"], tmp_path)
    killed = {}
    killer = threading.Thread(target=lambda: killed.update(at=kill_after(cut, cut_dir, 6)))
    killer.start()
    assert main(["run", str(wf), "--out", str(full_dir), "--verbose"]) == 0     # the uninterrupted run, meanwhile
    killer.join()
    printed = capsys.readouterr().out
    assert "[calib run] hub loads: MAP estimate converged after" in printed
    assert "stage = map, iteration = 1" in printed                      # --verbose: every optimizer iteration
    log_text = (full_dir / "calib.log").read_text()
    n_calls = count_model_calls(read_events(full_dir))["computed"]
    # the log file has every model call (the calibration's at its 24 points, the advice's at its candidates)
    assert len(re.findall(r"calib\.history: stage 1: hub loads: (?:evaluate|jacobian) of \d+ points", log_text)) \
        == n_calls
    assert "INFO    calib.workflow: [calib run] report:" in log_text
    iterations = [e for e in read_events(full_dir) if e["event"] == "iteration"]
    assert iterations and {"stage", "iteration", "cost"} <= set(iterations[0])
    events = read_events(cut_dir)
    assert not any(e["event"] == "finished" for e in events), "the run finished before the kill"
    assert not (cut_dir / "report.html").exists()
    assert assert_complete_files(cut_dir) >= 3

    assert main(["run", "--resume", str(cut_dir), "--quiet"]) == 0
    assert capsys.readouterr().out == ""                                # --quiet
    stage = "stage1_hub_loads"
    full_res = json.loads((full_dir / stage / "result.json").read_text())
    resumed = json.loads((cut_dir / stage / "result.json").read_text())
    with np.load(full_dir / stage / "result.npz") as a, np.load(cut_dir / stage / "result.npz") as b:
        p_full, p_res = a["estimate.p_hat"], b["estimate.p_hat"]
        scale = a["estimate.scale"]
        np.testing.assert_array_equal(b["identifiability.retained"], a["identifiability.retained"])
        np.testing.assert_allclose(b["uncertainty.cov_p"], a["uncertainty.cov_p"], rtol=1e-6, atol=0)
    # the optimizer stops at a relative cost decrease of `tolerance`; the replay is exact, so far inside it
    assert np.max(np.abs(p_res - p_full) / scale) <= 1e-6
    assert resumed["estimate"]["status"] == full_res["estimate"]["status"] == "converged"
    assert resumed["fit"]["chi2_after"] == pytest.approx(full_res["fit"]["chi2_after"], rel=1e-9)

    n_full = count_model_calls(read_events(full_dir))
    resumed_calls = count_model_calls(read_events(cut_dir), since_last_start=True)
    assert n_full["replayed"] == 0 and n_full["computed"] >= 10
    # what the killed run computed is read back, not computed again
    assert resumed_calls["replayed"] >= killed["at"] - 1
    assert resumed_calls["computed"] < n_full["computed"]
    assert resumed_calls["computed"] + resumed_calls["replayed"] == n_full["computed"]
    assert (cut_dir / "report.html").is_file()
    assert assert_complete_files(cut_dir) >= 10


def test_kill_while_results_and_figures_are_written_leaves_no_partial_file(tmp_path):
    """SIGKILL while the result, the figures and the report are being written."""
    wf = small_workflow(tmp_path)
    out = tmp_path / "o"
    proc = start(["run", wf, "--out", out, "--quiet"], tmp_path)
    deadline = time.monotonic() + 240
    while not (out / "stage1_hub_loads" / "result.json").exists():
        assert proc.poll() is None, proc.stderr.read()[-3000:]
        assert time.monotonic() < deadline
        time.sleep(0.002)
    time.sleep(0.3)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert not (out / "report.html").exists(), "the run ended before the kill"
    assert assert_complete_files(out) >= 3


def test_resume_refuses_changed_inputs(tmp_path):
    out = tmp_path / "o"
    open_history(out, {"command": "run", "inputs": {"workflow file": "a" * 64, "measurement file": "b" * 64}},
                 resume=False)
    with pytest.raises(InputError, match="measurement file") as exc:
        open_history(out, {"command": "run", "inputs": {"workflow file": "a" * 64, "measurement file": "c" * 64}},
                     resume=True)
    assert "workflow file" not in str(exc.value)
    with pytest.raises(InputError, match="calib run"):
        open_history(out, {"command": "diagnose", "inputs": {}}, resume=True)
    with pytest.raises(InputError, match="nothing to resume"):
        open_history(tmp_path / "empty", {"command": "run", "inputs": {}}, resume=True)


def test_resume_of_an_edited_workflow_is_refused_by_the_command(tmp_path, capsys):
    from calib.cli import main

    wf = small_workflow(tmp_path)
    out = tmp_path / "o"
    open_history(out, {"command": "run", "workflow": str(wf), "inputs": {"workflow file": "0" * 64}}, resume=False)
    assert main(["run", "--resume", str(out)]) == 2
    err = capsys.readouterr().err
    assert "workflow file" in err and "changed" in err


def test_incomplete_last_line_is_dropped_on_resume(tmp_path):
    from calib.history import History

    h = open_history(tmp_path, {"command": "run", "inputs": {}}, resume=False)
    h.append({"event": "evaluate", "key": "k1"}, {"values": np.ones(3)})
    with open(h.events_path, "ab") as fh:
        fh.write(b'{"event": "evaluate", "key": "k2", "rec')      # a kill in the middle of an append
    h2 = open_history(tmp_path, {"command": "run", "inputs": {}}, resume=True)
    assert isinstance(h2, History) and h2.lookup("k1") is not None and h2.lookup("k2") is None
    h2.event("start")
    assert [e["event"] for e in read_events(tmp_path)] == ["evaluate", "start"]


# ----------------------------------------------------------------------------- FMU diagnosis
FMU_CONFIG = """
[rotor]
name = "nrel5mw"

[model]
kind = "fmu"
variant = "A"
switches = { tower_shadow = false, shear = false, yaw = false, flexible_blades = false, gravity = false, skewed_wake = false, dynamic_inflow = false, tip_loss = true, hub_loss = true }
settings = { shaft_tilt = 0.0, max_internal_step = 0.1, max_azimuth_step = 10.0 }
steady = { steps_per_revolution = 8, settle_revolutions = 0, average_revolutions = 2, perturbation_settle_revolutions = 0, perturbation_average_revolutions = 1 }
jacobian = { warm_start = true }

[grid]
alpha_nodes_deg = [0.0, 10.0]
eta_nodes = [0.6, 1.0]

[calibration]
noise = "known"
max_iterations = 3
max_relinearizations = 1
tolerance = 1e-6

[diagnosis]
candidates = ["pitch_offset_blade1", "stall_delay_strength"]
max_effects = 1
recalibrate = false

[executor]
kind = "process"
workers = 2
"""
FMU_CHANNELS = ["power", "thrust", "root_flap_moment"]


def fmu_campaign(tmp_path: Path, config_text: str = FMU_CONFIG, channels=tuple(FMU_CHANNELS), offset: float = 1.0,
                 relative_sigma: float = 0.01, seed: int = 5) -> tuple[Path, Path]:
    """A config of the bundled FMU (variant A, 8 correction nodes, quasi-steady and short windows)
    and four operating points of that FMU with blade 1 pitched by ``offset`` [deg], noise
    ``relative_sigma`` of each channel's RMS, in ``channels``."""
    from calib.corrections import CorrectionGrid
    from calib.measurements import synthesize
    from calib.models.from_config import model_from_workflow
    from calib.rotor.library import load_rotor
    from calib.tomlfile import read_toml
    from calib.types import OperatingConditions

    channels = list(channels)
    config = tmp_path / "diagnose.toml"
    config.write_text(config_text)
    cfg = read_toml(config, "config")
    grid = CorrectionGrid(cfg["grid"]["alpha_nodes_deg"], cfg["grid"]["eta_nodes"])
    truth = model_from_workflow({**cfg["model"], "parameters": ["pitch_offset_blade1"], "corrections": False},
                                {"name": "nrel5mw"}, channels, str(config), tmp_path, grid=grid)
    rotor = load_rotor("nrel5mw")
    T, P = np.meshgrid([6.0, 9.0], [0.0, 4.0], indexing="ij")
    v = 10.0 * np.pi / 30 * rotor.rotor_radius / T.ravel()
    meas = synthesize(truth, np.array([offset]), OperatingConditions(v, np.full(v.size, 10.0), P.ravel()),
                      relative_sigma={c: relative_sigma for c in channels}, seed=seed)
    truth.close()
    data = tmp_path / "campaign.csv"
    meas.write_csv(data)
    return config, data


def test_killed_fmu_diagnosis_resumes_to_the_uninterrupted_result(tmp_path):
    """``calib diagnose`` of an FMU (process executor, 2 workers) killed with SIGKILL during the
    localization, then ``calib diagnose --resume DIR``: the same diagnosis, and no chunk of
    simulations the killed run completed is simulated again."""
    from calib.cli import main
    from calib.diagnosis.command import run_diagnose

    config, data = fmu_campaign(tmp_path)
    full_dir, cut_dir = tmp_path / "full", tmp_path / "cut"
    cut = start(["diagnose", "--data", data, "--config", config, "--out", cut_dir, "--quiet"], tmp_path)
    killed = {}
    killer = threading.Thread(target=lambda: killed.update(at=kill_after(cut, cut_dir, 6)))
    killer.start()
    full = run_diagnose(None, str(data), str(full_dir), str(config), printer=lambda line: None)
    killer.join()
    assert full.effect == "pitch_offset_blade1"
    assert not any(e["event"] == "finished" for e in read_events(cut_dir))
    assert not (cut_dir / "diagnosis.json").exists()
    assert assert_complete_files(cut_dir) >= 3

    assert main(["diagnose", "--resume", str(cut_dir), "--quiet"]) == 0
    a = json.loads((full_dir / "diagnosis.json").read_text())
    b = json.loads((cut_dir / "diagnosis.json").read_text())
    assert b["effect"] == a["effect"] == "pitch_offset_blade1"
    fit_a, fit_b = (next(c for c in d["candidates"] if c["name"] == "pitch_offset_blade1") for d in (a, b))
    value, std = fit_a["parameters"][0]["value"], fit_a["parameters"][0]["std"]
    assert abs(value - 1.0) <= 3 * std
    # the replay is exact: the estimate agrees far inside the optimizer's tolerance
    assert fit_b["parameters"][0]["value"] == pytest.approx(value, rel=1e-9, abs=1e-12)
    assert b["before"]["chi2"] == pytest.approx(a["before"]["chi2"], rel=1e-12)
    assert b["with_effects"]["chi2"] == pytest.approx(a["with_effects"]["chi2"], rel=1e-9)
    assert b["localization"]["n_retained"] == a["localization"]["n_retained"]
    assert b["localization"]["chi2_per_dof_after"] == pytest.approx(a["localization"]["chi2_per_dof_after"], rel=1e-9)

    n_full = count_model_calls(read_events(full_dir))
    resumed = count_model_calls(read_events(cut_dir), since_last_start=True)
    assert resumed["replayed"] >= killed["at"] - 1
    assert resumed["computed"] < n_full["computed"]
    assert resumed["computed_points"] < n_full["computed_points"]
    assert assert_complete_files(cut_dir) >= 10


def test_rotor_digest_sees_an_edited_polar_and_not_its_path():
    """The manifest's rotor digest: a changed polar value (e.g. an airfoil file edited between the
    kill and --resume) changes it; the same data loaded from elsewhere (``source``) does not."""
    import dataclasses

    from calib.history import content_digest
    from calib.rotor.library import load_rotor

    rotor = load_rotor("phase_vi")
    table = rotor.airfoils[0].tables[0]
    cl = table.cl.copy()
    cl[len(cl) // 2] += 1e-6
    edited_airfoil = dataclasses.replace(rotor.airfoils[0], tables=(dataclasses.replace(table, cl=cl),)
                                         + rotor.airfoils[0].tables[1:])
    edited = dataclasses.replace(rotor, airfoils=(edited_airfoil,) + rotor.airfoils[1:])
    moved = dataclasses.replace(rotor, source="/elsewhere/phase_vi.fst")
    assert content_digest(edited) != content_digest(rotor)
    assert content_digest(moved) == content_digest(rotor) == content_digest(load_rotor("phase_vi"))


def test_a_call_repeated_within_a_fresh_run_is_not_counted_as_read_back(tmp_path):
    """A fresh output folder reported "1 read back" (issue 35): a call the run had made already, answered
    from its own record, is counted as repeated; "read back" counts only records of an earlier run."""
    from twin_model import TwinModel, twin_conditions

    from calib.history import open_history
    from calib.models.recorded_model import recorded
    from calib.types import nominal_vector

    model = TwinModel(channels=("power",))
    p, cond = nominal_vector(model.parameters), twin_conditions()
    hist = open_history(tmp_path, {"command": "test", "inputs": {}}, resume=False)
    rec = recorded(model, hist, "test")
    rec.evaluate(p, cond)
    rec.evaluate(p, cond)
    assert (hist.computed, hist.replayed, hist.repeated) == (1, 0, 1)
    assert "1 computed, 0 read back from" in hist.calls_sentence() and "1 repeated within this run" in \
        hist.calls_sentence()
    again = open_history(tmp_path, {"command": "test", "inputs": {}}, resume=True)
    recorded(model, again, "test").evaluate(p, cond)
    assert (again.computed, again.replayed, again.repeated) == (0, 1, 0)
