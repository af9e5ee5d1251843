"""Step cost of the NREL 5-MW rotor FMUs: simulated seconds per wall-clock second.

Both variants (A: FMI 2.0, B: FMI 3.0) run 60 s of simulated time at rated conditions
(11.4 m/s, 12.1 rpm) with everything on (flexible blades, Oye dynamic inflow, tower shadow,
shear, gravity), communication step 0.05 s, through plain ``fmpy.simulate_fmu``; the
instance set-up (extraction, instantiation) is timed separately. The build itself is not
timed (it is cached).
"""

from __future__ import annotations

import time

import numpy as np

SIM_TIME = 60.0
STEP = 0.05


def _run_variant(variant: str) -> dict:
    import fmpy
    from fmpy import extract
    from calib.fmu.build import build_fmu
    path = str(build_fmu(variant))
    unzip = extract(path)
    start = ({"wind_speed": 11.4, "rotor_speed": 12.1} if variant == "A"
             else {"Wind.Vhub": 11.4, "Rotor.Omega": 12.1 * np.pi / 30})
    t0 = time.perf_counter()
    fmpy.simulate_fmu(unzip, stop_time=1.0, step_size=STEP, output_interval=STEP, start_values=start)
    t_short = time.perf_counter() - t0
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        fmpy.simulate_fmu(unzip, stop_time=SIM_TIME, step_size=STEP, output_interval=STEP, start_values=start)
        best = min(best, time.perf_counter() - t0)
    per_step = (best - t_short) / ((SIM_TIME - 1.0) / STEP)
    return {"realtime_factor": SIM_TIME / best, "wall_s_per_60s": best,
            "step_cost_ms": 1e3 * per_step, "realtime_factor_steps_only": STEP / per_step}


def run() -> dict:
    """Figures for ``make bench``: simulated seconds per wall second for both variants."""
    out = {}
    for v in ("A", "B"):
        try:
            r = _run_variant(v)
        except Exception as exc:  # noqa: BLE001 - reported, not raised
            return {"error": f"variant {v}: {exc}"}
        for k, val in r.items():
            out[f"fmu_{v}_{k}"] = val
    return out


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key:40s} {value:.4g}" if isinstance(value, float) else f"{key:40s} {value}")
