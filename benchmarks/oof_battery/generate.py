"""Generator of the out-of-family battery's data (runs in the project's environment).

For each set-up (``campaign.SETUPS``): the NREL 5-MW embedded in calib is exported with the
set-up's precone (``benchmarks/export_rotor.py``), ``ccblade_truth.py`` computes the
noise-free loads of every data set in the CCBlade environment ``.bench-venv`` (made by
``benchmarks/ccblade_env.sh`` when missing), and each seed's CSV gets 1 % Gaussian noise
(``campaign.noisy``) with the σ stated in ``_sigma`` columns, written by
``calib.measurements.Measurements.write_csv``. Also writes the calib config of each set-up
(``config_<set-up>.toml``: the ``[model]`` table stating the same tilt, precone, shear and
azimuth sectors as the CCBlade run) and computes the agreement of calib's native BEM with
CCBlade on the control (:func:`agreement`: the model-form tolerance's default).

Command line::

    .venv/bin/python benchmarks/oof_battery/generate.py [--seeds N] [--out DIR]
    .venv/bin/python benchmarks/oof_battery/generate.py --subset tests/data/oof

``--subset DIR`` writes the committed subset instead (``SUBSET_DATA_SETS`` in both set-ups,
seed ``campaign.SUBSET_SEED``, the configs and ``PROVENANCE.md``).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
BENCH = HERE.parent
ROOT = BENCH.parent
sys.path.insert(0, str(BENCH))

from oof_battery import campaign  # noqa: E402

VENV = Path(os.environ.get("CALIB_BENCH_VENV", ROOT / ".bench-venv"))
OUT_DIR = ROOT / "bench_output" / "oof_battery"
ROTOR = "nrel5mw"
#: Data sets of the committed subset: the control and three effects calib's diagnosis names.
SUBSET_DATA_SETS = ("control", "reynolds_following", "leading_edge_erosion", "rotational_augmentation")
CCBLADE_TIMEOUT_S = 1800


def ensure_ccblade_env() -> Path:
    """The CCBlade interpreter, after ``ccblade_env.sh`` made or checked ``.bench-venv``."""
    proc = subprocess.run(["bash", str(BENCH / "ccblade_env.sh")], capture_output=True, text=True,
                          env={**os.environ, "CALIB_BENCH_VENV": str(VENV)}, timeout=CCBLADE_TIMEOUT_S)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmarks/ccblade_env.sh failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return VENV / "bin" / "python"


def setup_rotor(name: str):
    """calib's rotor with the set-up's tilt and precone (what ``[model] tilt/precone`` make of it)."""
    from calib.rotor.library import load_rotor

    s = campaign.SETUPS[name]
    return dataclasses.replace(load_rotor(ROTOR), tilt_deg=s["tilt_deg"], precone_deg=s["precone_deg"])


def ccblade_truth(setup: str, work: Path, data_sets=None) -> dict:
    """Noise-free CCBlade loads of ``data_sets`` (default all) in one set-up (``ccblade_truth.py``)."""
    from export_rotor import rotor_to_dict
    from calib.rotor.library import load_rotor

    work.mkdir(parents=True, exist_ok=True)
    s = campaign.SETUPS[setup]
    names = list(data_sets or campaign.DATA_SETS)
    rotor_json, spec_json, out_json = (work / f"rotor_{setup}.json", work / f"spec_{setup}.json",
                                       work / f"truth_{setup}.json")
    rotor_json.write_text(json.dumps(rotor_to_dict(setup_rotor(setup))))
    spec = {**campaign.operating_points(load_rotor(ROTOR).rotor_radius), "tilt_deg": s["tilt_deg"],
            "shear_exp": s["shear_exp"], "n_sector": s["n_sector"],
            "data_sets": [{"name": n, "hidden": campaign.DATA_SETS[n]["hidden"]} for n in names]}
    spec_json.write_text(json.dumps(spec))
    py = ensure_ccblade_env()
    proc = subprocess.run([str(py), str(HERE / "ccblade_truth.py"), str(rotor_json), str(spec_json), str(out_json)],
                          capture_output=True, text=True, timeout=CCBLADE_TIMEOUT_S)
    for line in proc.stdout.splitlines():
        print(f"[oof generate] {setup}: {line}", flush=True)
    if proc.returncode != 0:
        raise RuntimeError(f"ccblade_truth.py failed for set-up {setup} (exit {proc.returncode}):\n"
                           f"{proc.stderr[-3000:]}")
    truth = json.loads(out_json.read_text())
    for n, d in truth["data_sets"].items():
        if not all(d["converged"]):
            bad = [k for k, ok in enumerate(d["converged"]) if not ok]
            raise RuntimeError(f"CCBlade did not converge at points {bad} of data set {n}, set-up {setup}")
    truth["points"] = {k: spec[k] for k in ("wind_speed", "rotor_speed_rpm", "pitch_deg", "tsr")}
    return truth


def truth_matrix(truth: dict, data_set: str) -> np.ndarray:
    """(n_points, n_channels) noise-free values of one data set in :data:`campaign.CHANNELS` order."""
    d = truth["data_sets"][data_set]
    return np.column_stack([np.asarray(d[campaign.CCBLADE_KEYS[c]], float) for c in campaign.CHANNELS])


def noisy_csv(y: np.ndarray, points: dict, seed: int, source: str, path: Path) -> Path:
    """The battery's CSV of noise-free loads ``y`` (n_points, channels of ``campaign.CHANNELS``) at
    ``points`` (``wind_speed``, ``rotor_speed_rpm``, ``pitch_deg``): the battery's noise of seed
    ``seed``, σ columns, SI units, ``source`` in its header."""
    from calib.measurements import Measurements
    from calib.types import OperatingConditions

    sigma = campaign.noise_sigma(y)
    cond = OperatingConditions(points["wind_speed"], points["rotor_speed_rpm"], points["pitch_deg"])
    meas = Measurements(cond, campaign.CHANNELS, campaign.noisy(y, sigma, seed), np.broadcast_to(sigma, y.shape),
                        source=source)
    return meas.write_csv(path)


def write_csv(truth: dict, setup: str, data_set: str, seed: int, path: Path) -> Path:
    """One data set's CSV: noise of seed ``seed`` on the CCBlade truth (:func:`noisy_csv`)."""
    return noisy_csv(truth_matrix(truth, data_set), truth["points"], seed,
                     f"benchmarks/oof_battery/generate.py: WISDEM CCBlade {truth['wisdem_version']}, set-up {setup}, "
                     f"data set {data_set}, noise seed {seed}", path)


def config_text(setup: str, recalibrate: bool = False, tolerance: dict | None = None) -> str:
    """calib's diagnose config for a set-up: ``[model]`` states the CCBlade run's set-up.

    Parameters
    ----------
    setup : str
        A key of ``campaign.SETUPS``.
    recalibrate : bool
        ``[diagnosis] recalibrate``. Off by default: the verdict (``effect``, ``effects``) is
        settled before the recalibration, which only adds time.
    tolerance : dict, optional
        ``[diagnosis] model_form_tolerance``, channel -> fraction [-] (default: calib's default).
    """
    s = campaign.SETUPS[setup]
    tol = "" if not tolerance else (
        "model_form_tolerance = { " + ", ".join(f"{c} = {float(v)!r}" for c, v in tolerance.items()) + " }\n")
    return (f"# calib diagnose config of the out-of-family battery, set-up '{setup}': {s['describe']}.\n"
            "# Written by benchmarks/oof_battery/generate.py; the same set-up as the CCBlade run of the data.\n"
            f"[rotor]\nname = \"{ROTOR}\"\n\n"
            f"[model]\ntilt = {s['tilt_deg']!r}\nprecone = {s['precone_deg']!r}\nuse_tilt = true\n"
            f"shear_exponent = {s['shear_exp']!r}\nn_sectors = {s['n_sector']}\n\n"
            f"[diagnosis]\nrecalibrate = {'true' if recalibrate else 'false'}\n{tol}")


def agreement(truth: dict, setup: str, smoothing=None) -> dict:
    """calib's native BEM against CCBlade on the control: relative difference per channel.

    Parameters
    ----------
    truth : dict
        :func:`ccblade_truth` of the set-up (its ``control`` data set: no effect, no noise).
    setup : str
    smoothing : tuple, optional
        ``BemSettings.polar_smoothing`` (default None: calib's default, its polars as given;
        ``(0.01, 0.001)`` is CCAirfoil's spline: a diagnostic of what the difference is).

    Returns
    -------
    dict
        Per channel ``rms_pct``, ``max_pct``, ``mean_pct`` of 100 (calib − CCBlade)/CCBlade over
        the operating points [%], and ``worst_point`` (tip-speed ratio, pitch, rotor speed).
    """
    from calib.bem import BemSettings, solve_bem
    from calib.types import OperatingConditions

    s = campaign.SETUPS[setup]
    pts = truth["points"]
    cond = OperatingConditions(pts["wind_speed"], pts["rotor_speed_rpm"], pts["pitch_deg"])
    res = solve_bem(setup_rotor(setup), cond, BemSettings(shear_exponent=s["shear_exp"], n_sectors=s["n_sector"],
                                                          use_tilt=True, polar_smoothing=smoothing))
    if not np.all(res.ok):
        raise RuntimeError(f"calib's BEM failed at {int((~res.ok).sum())} points of set-up {setup}")
    cc = truth_matrix(truth, "control")
    out = {}
    for j, ch in enumerate(campaign.CHANNELS):
        d = 100.0 * (np.asarray(getattr(res, ch), float) / cc[:, j] - 1.0)
        k = int(np.argmax(np.abs(d)))
        out[ch] = {"rms_pct": float(np.sqrt(np.mean(d ** 2))), "max_pct": float(np.max(np.abs(d))),
                   "mean_pct": float(np.mean(d)),
                   "worst_point": {"tsr": pts["tsr"][k], "pitch_deg": pts["pitch_deg"][k],
                                   "rotor_speed_rpm": pts["rotor_speed_rpm"][k]}}
    return out


def versions(truth: dict) -> dict:
    import calib
    def git(*args) -> str:
        try:
            return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True,
                                  timeout=30).stdout.rstrip()
        except (OSError, subprocess.TimeoutExpired):
            return ""
    dirty = [line[3:] for line in git("status", "--porcelain", "--", "calib").splitlines()]
    return {"wisdem": truth["wisdem_version"], "ccblade_numpy": truth.get("numpy_version"),
            "calib": getattr(calib, "__version__", "?"), "calib_commit": git("rev-parse", "HEAD"),
            "calib_uncommitted_files": dirty, "numpy": np.__version__, "python": platform.python_version()}


def tolerance_from(agreement: dict) -> dict:
    """Per channel, the larger RMS relative difference calib − CCBlade of the set-ups, as a fraction [-]."""
    return {ch: max(a["default"][ch]["rms_pct"] for a in agreement.values()) / 100.0 for ch in campaign.CHANNELS}


def generate(n_seeds: int = 20, out: Path = OUT_DIR, data_sets=None, say=print, tolerance: str | None = None) -> dict:
    """Truth, CSVs of ``n_seeds`` seeds per (set-up, data set), configs and the BEM agreement.

    ``tolerance="measured"`` writes the configs with ``[diagnosis] model_form_tolerance`` set to
    :func:`tolerance_from` the agreement just measured (needs the ``control`` data set).

    Returns
    -------
    dict
        ``files`` [(set-up, data set, seed, csv path)], ``configs`` {set-up: path},
        ``agreement`` {set-up: {"default": ..., "ccairfoil_smoothing": ...}}, ``truth_details``,
        ``parameters`` (hidden-effect amplitudes), ``effect_size`` (χ²/point of each truth
        against calib's nominal model at the stated σ, no noise), ``versions``, ``seconds``.
    """
    if tolerance not in (None, "measured"):
        raise ValueError(f"tolerance must be None or 'measured', got {tolerance!r}")
    t0 = time.perf_counter()
    out = Path(out)
    names = list(data_sets or campaign.DATA_SETS)
    files, configs, agree, details, sizes = [], {}, {}, {}, {}
    truth = None
    for setup in campaign.SETUPS:
        truth = ccblade_truth(setup, out / "truth", names)
        (out / "truth" / f"truth_{setup}.json").write_text(json.dumps(truth))
        agree[setup] = {"default": agreement(truth, setup) if "control" in names else None,
                        "ccairfoil_smoothing": agreement(truth, setup, (0.01, 0.001)) if "control" in names else None}
        details[setup] = {n: truth["data_sets"][n]["details"] for n in names}
        sizes[setup] = effect_sizes(truth, setup, names)
        for n in names:
            for k in range(n_seeds):
                seed = campaign.SEED0 + k
                files.append((setup, n, seed, write_csv(truth, setup, n, seed, out / "data" / setup /
                                                          f"{n}_seed{seed}.csv")))
        say(f"[oof generate] {setup}: {len(names)} data sets x {n_seeds} seeds written to {out / 'data' / setup}")
    tol = tolerance_from(agree) if tolerance == "measured" else None
    for setup in campaign.SETUPS:
        configs[setup] = out / f"config_{setup}.toml"
        configs[setup].write_text(config_text(setup, tolerance=tol))
    return {"files": files, "configs": configs, "agreement": agree, "tolerance": tol, "truth_details": details,
            "parameters": truth["parameters"], "effect_size": sizes, "versions": versions(truth),
            "seconds": time.perf_counter() - t0}


def effect_sizes(truth: dict, setup: str, names) -> dict:
    """χ² per residual of each data set's noise-free truth against calib's nominal BEM (σ as stated) [-]."""
    from calib.bem import BemSettings, solve_bem
    from calib.types import OperatingConditions

    s = campaign.SETUPS[setup]
    pts = truth["points"]
    cond = OperatingConditions(pts["wind_speed"], pts["rotor_speed_rpm"], pts["pitch_deg"])
    res = solve_bem(setup_rotor(setup), cond, BemSettings(shear_exponent=s["shear_exp"], n_sectors=s["n_sector"],
                                                          use_tilt=True))
    y0 = np.column_stack([np.asarray(getattr(res, c), float) for c in campaign.CHANNELS])
    out = {}
    for n in names:
        y = truth_matrix(truth, n)
        out[n] = float(np.mean(((y - y0) / campaign.noise_sigma(y)) ** 2))
    return out


def effect_lines(names) -> str:
    """Markdown bullets: each data set's hidden effect in words and the names that count as right."""
    return "\n".join(f"  - `{n}`: {campaign.DATA_SETS[n]['describe']} (right: "
                     f"{', '.join(campaign.DATA_SETS[n]['right'])})" for n in names)


def write_subset(target: Path, command: str, say=print) -> list[Path]:
    """The committed subset: ``SUBSET_DATA_SETS`` in both set-ups at ``SUBSET_SEED``, configs, PROVENANCE.md."""
    target = Path(target)
    target.mkdir(parents=True, exist_ok=True)
    written, truth = [], None
    with_work = OUT_DIR / "subset_truth"
    for setup in campaign.SETUPS:
        truth = ccblade_truth(setup, with_work, SUBSET_DATA_SETS)
        for n in SUBSET_DATA_SETS:
            written.append(write_csv(truth, setup, n, campaign.SUBSET_SEED, target / f"{setup}_{n}.csv"))
        cfg = target / f"config_{setup}.toml"
        cfg.write_text(config_text(setup))
        written.append(cfg)
    v = versions(truth)
    rows = "\n".join(f"| `{p.name}` | {p.stat().st_size} |" for p in written)
    dirty = (f" (working tree with uncommitted changes in {', '.join(v['calib_uncommitted_files'])})"
             if v["calib_uncommitted_files"] else "")
    text = f"""# Provenance of tests/data/oof/

Out-of-family subset of the battery of issue 25, used by `tests/test_oof_battery.py`.
**Synthetic data from another code, not measurements.**

- Made by `benchmarks/oof_battery/generate.py` (function `write_subset`), command:

      {command}

- Date: {datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC')}
- Truth code: WISDEM {v['wisdem']} CCBlade (`.bench-venv`, made by `benchmarks/ccblade_env.sh`;
  numpy {v['ccblade_numpy']}), run by `benchmarks/oof_battery/ccblade_truth.py` through
  `benchmarks/ccblade_runner.py`'s `build_rotor`.
- calib {v['calib']} at commit `{v['calib_commit'] or '?'}`{dirty} (used for the rotor export and the
  CSV writer only), python {v['python']}, numpy {v['numpy']}.
- Rotor: calib's embedded `nrel5mw` with its own polars. Operating points: 63 (the demo campaign's
  32 at 9 rpm and 31 at 6 rpm; `benchmarks/oof_battery/campaign.py`). Channels: power, thrust,
  torque, hub_flap_moment (CCBlade's `Mb`, the flap moment of one blade about the rotor centre).
- Noise: Gaussian, 1-σ = 1 % of each channel's RMS over the points (stated in the `_sigma`
  columns), seed {campaign.SUBSET_SEED} (the battery's seeds start at {campaign.SEED0}).
- Set-ups: `rigid` ({campaign.SETUPS['rigid']['describe']}) and `tilted`
  ({campaign.SETUPS['tilted']['describe']}); `config_<set-up>.toml` states the same set-up to
  `calib diagnose`.
- Data sets (hidden effect written in CCBlade's world; forms in `benchmarks/oof_battery/hidden_effects.py`):
{effect_lines(SUBSET_DATA_SETS)}

Do not edit these files by hand: run the command above again (the date and versions change).

| file | bytes |
|---|---|
{rows}
"""
    (target / "PROVENANCE.md").write_text(text)
    say(f"[oof generate] subset: {len(written)} files and PROVENANCE.md in {target}")
    return written + [target / "PROVENANCE.md"]


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="noise seeds per (set-up, data set) (default 20)")
    ap.add_argument("--out", default=str(OUT_DIR), help=f"output folder (default {OUT_DIR})")
    ap.add_argument("--subset", metavar="DIR", help="write the committed subset into DIR instead")
    args = ap.parse_args(argv)
    if args.subset:
        cmd = ".venv/bin/python benchmarks/oof_battery/generate.py --subset " + args.subset
        write_subset(Path(args.subset), cmd)
        return 0
    res = generate(args.seeds, Path(args.out))
    print(json.dumps({k: v for k, v in res.items() if k not in ("files", "configs")}, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
