"""The FMU adapter (calib.models.fmu_model.FmuModel): Jacobian warm start, overhead, parallelism.

Figures (variant A, NREL 5-MW, a 3 x 2 correction grid: 12 parameters; best of repeats):

- ``warm_vs_cold_jacobian_ratio``: wall time of a central-difference Jacobian per operating
  point with perturbed runs restored from the settled base state (settle 0, average 1
  revolution) over the same with every perturbed run settled from scratch (the mapping's
  2 + 2 revolutions); quasi-steady physics (rigid blades, no dynamic inflow), where the
  restored state is periodic and a parameter step acts at once. Target <= 0.3. With the
  derivative error of each against a long-settled reference.
- ``full_physics_*``: the same comparison with the FMU's default physics (Oye dynamic
  inflow, flexible blades, tower, shear): a restored state carries the base point's filtered
  induction, which relaxes over ~2 revolutions, so the warm difference is wrong by the lag
  unless it settles longer; these FMUs start every cold run in the equilibrium of its own
  parameters. This is why the bundled mappings turn warm start off.
- ``adapter_overhead_ratio``: one steady evaluation through ``FmuModel.evaluate`` (in a worker
  process, and in-process) over a raw fmpy loop doing the same steps (instantiate once;
  reset, set, initialize, doStep + getReal per step, mean). Target <= 1.10.
- ``parallel_efficiency_2_workers``: serial Jacobian time / (2 x the time on a warmed-up
  2-process pool). Target >= 0.8. The machine's load average is reported with it: on a
  shared 2-core machine other processes take part of the second core.
- ModestPy: whether it installs in ``.bench-venv-modestpy`` (never the project venv).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
QUASI_STEADY = dict(dynamic_inflow=False, flexible_blades=False, tower_shadow=False, shear=False, gravity=False)
CHANNELS = ["power", "thrust", "root_flap_moment"]


def _best(fn, repeats=2):
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def _setup():
    from calib.corrections import CorrectionGrid
    from calib.fmu.build import build_fmu
    from calib.types import OperatingConditions
    path = build_fmu("A", None, CorrectionGrid([0.0, 5.0, 10.0], [0.4, 0.9]))
    cond = OperatingConditions([8.0, 11.4], [9.2, 12.1], [0.0, 0.0])
    return path, cond


def _model(path, switches, steady=None, warm=False, executor=None, isolate=False):
    from calib.fmu.build import mapping_path
    from calib.models.fmu_model import FmuModel
    return FmuModel(path, mapping_path("A"), CHANNELS, parameters=[], switches=switches, steady=steady or {},
                    jacobian=dict(warm_start=warm), executor=executor, isolate=isolate)


def warm_vs_cold(path, cond) -> dict:
    out = {}
    warm_steady = dict(perturbation_settle_revolutions=0, perturbation_average_revolutions=1)
    for label, switches in (("", QUASI_STEADY), ("full_physics_", {})):
        p = np.zeros(12)
        ref = _model(path, switches, dict(settle_revolutions=8, average_revolutions=4))
        _, G_ref = ref.jacobian(p, cond)
        scale = np.abs(G_ref).max(axis=2, keepdims=True)
        runs = {"cold": _model(path, switches), "warm": _model(path, switches, warm_steady, warm=True)}
        if label:
            runs["warm_settle2"] = _model(path, switches, dict(perturbation_settle_revolutions=2,
                                                               perturbation_average_revolutions=2), warm=True)
        times = {}
        for name, m in runs.items():
            t, (ev, G) = _best(lambda m=m: m.jacobian(p, cond))
            times[name] = t / len(cond)
            out[f"{label}{name}_jacobian_s_per_point"] = times[name]
            out[f"{label}{name}_jacobian_max_rel_error"] = float(np.max(np.abs(G - G_ref) / scale))
            out[f"{label}{name}_n_failed"] = int(ev.n_failed)
        out[f"{label}warm_vs_cold_jacobian_ratio"] = times["warm"] / times["cold"]
    return out


def overhead(path, cond) -> dict:
    """Per steady evaluation: the adapter against a raw fmpy loop doing the same steps."""
    import fmpy
    from fmpy.fmi2 import FMU2Slave
    from calib.fmu.build import mapping_path
    from calib.models.fmu_mapping import load_mapping

    m = load_mapping(mapping_path("A"))
    md = fmpy.read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    model = _model(path, QUASI_STEADY, isolate=False)
    unzip = model.unzip_dir
    rpm = float(cond.rotor_speed[1])
    h, n_settle, n_avg = m.steady.window(rpm)
    fixed = {m.switches[k].variable: int(m.switches[k].value(v)) for k, v in QUASI_STEADY.items()}
    reals = {e.variable: float(e.to_fmu(e.value)) for e in m.settings.values() if e.value is not None}
    outs = [vr[m.outputs[c].variable] for c in CHANNELS] + [vr["azimuth"]]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="raw")
    fmu.instantiate()

    def raw():
        fmu.reset()
        fmu.setupExperiment(startTime=0.0)
        fmu.setInteger([vr[k] for k in fixed], list(fixed.values()))
        fmu.setReal([vr[k] for k in reals], list(reals.values()))
        fmu.setReal([vr["wind_speed"], vr["rotor_speed"], vr["collective_pitch"]],
                    [float(cond.wind_speed[1]), rpm, 0.0])
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        t, rows = 0.0, []
        for k in range(n_settle + n_avg):
            fmu.doStep(t, h)
            t += h
            if k >= n_settle:
                rows.append(fmu.getReal(outs))
        return np.mean(rows, axis=0)

    one = cond.subset([1])
    p = np.zeros(12)
    t_raw, y_raw = _best(raw, 3)
    t_in, ev = _best(lambda: model.evaluate(p, one), 3)
    iso = _model(path, QUASI_STEADY, isolate=True)
    iso.evaluate(p, one)                                   # start the worker process
    t_iso, ev2 = _best(lambda: iso.evaluate(p, one), 3)
    iso.close()
    fmu.terminate()
    fmu.freeInstance()
    assert np.allclose(ev.values[0], y_raw[:3], rtol=1e-12) and np.array_equal(ev.values, ev2.values)
    return {"raw_fmpy_loop_s": t_raw, "adapter_in_process_s": t_in, "adapter_worker_process_s": t_iso,
            "adapter_overhead_ratio": t_iso / t_raw, "adapter_overhead_ratio_in_process": t_in / t_raw,
            "steps_per_evaluation": n_settle + n_avg}


def parallel(path) -> dict:
    from calib.executors import ProcessExecutor, SerialExecutor
    from calib.types import OperatingConditions
    ws = np.linspace(6.0, 11.0, 8)
    cond = OperatingConditions(ws, np.full(8, 11.0), np.zeros(8))
    p = np.zeros(12)
    warm = dict(perturbation_settle_revolutions=0, perturbation_average_revolutions=1)
    serial = _model(path, QUASI_STEADY, warm, warm=True, executor=SerialExecutor(), isolate=True)
    serial.jacobian(p, cond.subset([0]))
    t1, (_, G1) = _best(lambda: serial.jacobian(p, cond), 1)
    serial.close()
    with ProcessExecutor(2) as pool:
        par = _model(path, QUASI_STEADY, warm, warm=True, executor=pool, isolate=True)
        par.jacobian(p, cond.subset([0, 1]))               # start both workers and their FMU processes
        t2, (_, G2) = _best(lambda: par.jacobian(p, cond), 1)
    assert np.array_equal(G1, G2)
    return {"serial_jacobian_8_points_s": t1, "pool2_jacobian_8_points_s": t2,
            "parallel_efficiency_2_workers": t1 / (2.0 * t2), "load_average_1min": os.getloadavg()[0],
            "cpu_count": os.cpu_count()}


def modestpy() -> dict:
    """Try ModestPy in its own venv (never the project's)."""
    venv = ROOT / ".bench-venv-modestpy"
    py = venv / "bin" / "python"
    if not py.exists():
        done = subprocess.run([sys.executable, "-m", "venv", str(venv)], capture_output=True, text=True)
        if done.returncode:
            return {"modestpy": f"venv creation failed: {done.stderr.strip()[-300:]}"}
    done = subprocess.run([str(py), "-m", "pip", "install", "-q", "modestpy"], capture_output=True, text=True,
                          timeout=1800)
    if done.returncode:
        return {"modestpy": "not installable: " + " ".join(done.stderr.split())[-600:]}
    done = subprocess.run([str(py), "-c", "import modestpy, sys; print(getattr(modestpy, '__version__', '?'))"],
                          capture_output=True, text=True, timeout=300)
    if done.returncode:
        return {"modestpy": "installs but does not import: " + " ".join(done.stderr.split())[-600:]}
    return {"modestpy": f"installed (version {done.stdout.strip()}); comparison run not implemented"}


def run() -> dict:
    path, cond = _setup()
    out = {}
    for part in (lambda: warm_vs_cold(path, cond), lambda: overhead(path, cond), lambda: parallel(path), modestpy):
        try:
            out.update(part())
        except Exception as exc:  # noqa: BLE001 - reported, the other parts still run
            out.setdefault("errors", []).append(f"{type(exc).__name__}: {exc}")
    if "errors" in out:
        out["error"] = "; ".join(out.pop("errors"))
    return out


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key:45s} {value:.4g}" if isinstance(value, float) else f"{key:45s} {value}")
