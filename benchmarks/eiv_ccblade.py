"""The out-of-family errors-in-variables campaign: SCADA-like records whose outputs come from WISDEM's
CCBlade (issue 40, item 4), for ``benchmarks/bench_eiv.py``.

The records are those of :mod:`calib.calibration.eiv_campaign` (same true conditions, output noise and
condition errors per seed, drawn from the same random stream), with the noise-free outputs computed by
CCBlade instead of calib's native BEM: the NREL 5-MW without tilt and precone (the out-of-family
battery's ``rigid`` set-up: one azimuth sector, no shear), its own polars (no correction field: the
truth's field is zero, and the native BEM's difference from CCBlade, about 1 % in power, is model form
the calibration meets as a real rotor's would), channels ``power``, ``thrust`` and ``hub_flap_moment``
(CCBlade's ``P``, ``T``, ``Mb``). CCBlade runs once, in its own environment (``.bench-venv``, made by
``benchmarks/ccblade_env.sh``; ``CALIB_BENCH_VENV`` points elsewhere), on every seed's true conditions
batched in one call, at ρ = 1.225 kg/m³; each record's loads are scaled by ρ/1.225 (a BEM's
induction does not depend on ρ and the airfoil tables have one Reynolds number, so every load is
proportional to ρ). The result is cached in ``bench_output/eiv_ccblade/`` keyed by the conditions.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

#: calib's channels and CCBlade's output key of each.
CHANNELS = ("power", "thrust", "hub_flap_moment")
CCBLADE_KEYS = {"power": "P", "thrust": "T", "hub_flap_moment": "Mb"}
#: The air density of the CCBlade run [kg/m³].
RHO_RUN = 1.225
CACHE = ROOT / "bench_output" / "eiv_ccblade"


def campaign_spec():
    """The native campaign's :class:`calib.calibration.eiv_campaign.CampaignSpec` with the flap moment about the
    rotor centre in place of the root's (same 2 % of its RMS)."""
    from calib.calibration.eiv_campaign import CampaignSpec

    return CampaignSpec(output_sigma=(("power", 0.01), ("thrust", 0.02), ("hub_flap_moment", 0.02)))
TIMEOUT_S = 3600


def rigid_rotor():
    """The NREL 5-MW with tilt and precone 0 (what the CCBlade run and the fitted native model share)."""
    from calib.rotor.library import load_rotor

    return dataclasses.replace(load_rotor("nrel5mw"), tilt_deg=0.0, precone_deg=0.0)


def _venv_python() -> Path:
    venv = Path(os.environ.get("CALIB_BENCH_VENV", ROOT / ".bench-venv"))
    proc = subprocess.run(["bash", str(HERE / "ccblade_env.sh")], capture_output=True, text=True,
                          env={**os.environ, "CALIB_BENCH_VENV": str(venv)}, timeout=TIMEOUT_S)
    if proc.returncode != 0:
        raise RuntimeError(f"benchmarks/ccblade_env.sh failed (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
    return venv / "bin" / "python"


def ccblade_loads(conditions_list) -> tuple[list[np.ndarray], dict]:
    """CCBlade's noise-free outputs at every campaign's true conditions, one batched run (cached).

    Parameters
    ----------
    conditions_list : list of OperatingConditions
        The true conditions of each campaign (wind speed [m/s], rotor speed [rpm], pitch [deg], air
        density [kg/m³]).

    Returns
    -------
    list of ndarray, shape (n_records, 3)
        Per campaign, ``power`` [W], ``thrust`` [N], ``hub_flap_moment`` [N m] at its records' densities.
    dict
        ``wisdem_version`` and the number of points.
    """
    from export_rotor import rotor_to_dict

    sizes = [len(c) for c in conditions_list]
    v = np.concatenate([c.wind_speed for c in conditions_list])
    rpm = np.concatenate([c.rotor_speed for c in conditions_list])
    pitch = np.concatenate([c.pitch for c in conditions_list])
    rho = np.concatenate([c.air_density for c in conditions_list])
    rotor = rotor_to_dict(rigid_rotor())
    spec = {"wind_speed": v.tolist(), "rotor_speed_rpm": rpm.tolist(), "pitch_deg": pitch.tolist(),
            "tilt_deg": 0.0, "shear_exp": 0.0, "n_sector": 1, "rho": RHO_RUN,
            "data_sets": [{"name": "control", "hidden": "none"}]}
    key = hashlib.sha256(json.dumps([rotor, spec], sort_keys=True).encode()).hexdigest()[:16]
    CACHE.mkdir(parents=True, exist_ok=True)
    out = CACHE / f"truth_{key}.json"
    if not out.exists():
        rotor_json, spec_json = CACHE / f"rotor_{key}.json", CACHE / f"spec_{key}.json"
        rotor_json.write_text(json.dumps(rotor))
        spec_json.write_text(json.dumps(spec))
        tmp = out.with_suffix(".part")
        proc = subprocess.run([str(_venv_python()), str(HERE / "oof_battery" / "ccblade_truth.py"), str(rotor_json),
                               str(spec_json), str(tmp)], capture_output=True, text=True, timeout=TIMEOUT_S)
        if proc.returncode != 0:
            raise RuntimeError(f"ccblade_truth.py failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")
        tmp.replace(out)
    truth = json.loads(out.read_text())
    d = truth["data_sets"]["control"]
    if not all(d["converged"]):
        bad = [k for k, ok in enumerate(d["converged"]) if not ok]
        raise RuntimeError(f"CCBlade did not converge at {len(bad)} of {len(v)} points (first {bad[:5]})")
    y = np.column_stack([np.asarray(d[CCBLADE_KEYS[c]], float) for c in CHANNELS]) * (rho / RHO_RUN)[:, None]
    return list(np.split(y, np.cumsum(sizes)[:-1])), {"wisdem_version": truth["wisdem_version"], "n_points": len(v)}


def campaigns(spec, seeds) -> tuple[dict, dict]:
    """Every seed's campaign on the CCBlade truth: {seed: (Measurements, true conditions)} and the
    truth's provenance (:func:`ccblade_loads`)."""
    from calib.calibration.eiv_campaign import campaign_from_truth, true_conditions

    radius = float(rigid_rotor().rotor_radius)
    trues = {s: true_conditions(spec, radius, np.random.default_rng(s)) for s in seeds}
    loads, info = ccblade_loads([trues[s] for s in seeds])
    out = {}
    for s, y in zip(seeds, loads):
        rng = np.random.default_rng(s)
        true = true_conditions(spec, radius, rng)          # the same draws, advancing the stream
        out[s] = (campaign_from_truth(y, true, spec, rng, CHANNELS,
                                      f"WISDEM CCBlade {info['wisdem_version']}, seed {s}"), true)
    return out, info
