"""OpenOA's IEC power curve of La Haute Borne records: the independent reference of ``calib.scada``.

Runs in a Python environment with ``openoa`` installed, NOT calib's: openoa 3.2 pins
``pandas<3`` and calib's environment has pandas 3 (``benchmarks/bench_scada.py`` builds
``.bench-venv-openoa`` with ``python -m venv`` and ``pip install openoa==3.2``).
It imports nothing from calib.

    python benchmarks/openoa_reference.py <la-haute-borne csv> <out.json>

Per turbine, on its records in time order with the second record of a duplicated time stamp
dropped (``drop_duplicates(keep="first")``), it flags with OpenOA's own functions:

- ``filters.range_flag``: wind speed outside 0..40 m/s, power outside −5 %..110 % of rated, and
  NaN (range_flag flags a missing value);
- ``filters.unresponsive_flag(wind speed, threshold=3)``: frozen anemometer;
- ``filters.window_range_flag(ws, 5, 25, power, 1 % of rated, inf)``: stopped at operating wind;
- ``window_range_flag(ws, 5, 25, pitch, -inf, fine + 3°) & window_range_flag(power, -inf,
  90 % of rated, pitch, -inf, fine + 3°)``: pitched out below rated (curtailment), fine = −1°;

and bins the rest with ``openoa.utils.power_curve.IEC(ws, power, bin_width=0.5,
windspeed_start=0, windspeed_end=30)``, evaluated at the bin centres. These are the settings
``calib.scada.FilterSettings`` is given in ``tests/test_scada_openoa.py`` and
``benchmarks/bench_scada.py``.
"""

from __future__ import annotations

import json
import sys

import numpy as np
import openoa
import pandas as pd
from openoa.utils import filters, power_curve

RATED_KW = 2050.0
FINE_PITCH = -1.0
SETTINGS = {"rated_power_kw": RATED_KW, "wind_speed_range": [0.0, 40.0], "power_range_kw": [-0.05 * RATED_KW,
            1.1 * RATED_KW], "frozen_count": 3, "operating_window": [5.0, 25.0], "stop_power_kw": 0.01 * RATED_KW,
            "fine_pitch": FINE_PITCH, "pitch_margin": 3.0, "curtailment_fraction": 0.9}


def reference(csv_path: str) -> dict:
    df = pd.read_csv(csv_path)
    df["t"] = pd.to_datetime(df["Date_time"], utc=True)
    out = {}
    for name, g in df.groupby("Wind_turbine_name", sort=True):
        g = g.sort_values("t", kind="stable").drop_duplicates(subset="t", keep="first").reset_index(drop=True)
        ws, p, pitch = g["Ws_avg"], g["P_avg"], g["Ba_avg"]
        thr = FINE_PITCH + SETTINGS["pitch_margin"]
        flags = {
            "range": filters.range_flag(ws, 0.0, 40.0) | filters.range_flag(p, -0.05 * RATED_KW, 1.1 * RATED_KW)
            | filters.range_flag(pitch, -np.inf, np.inf),
            "unresponsive": filters.unresponsive_flag(ws, 3),
            "stopped": filters.window_range_flag(ws, 5.0, 25.0, p, 0.01 * RATED_KW, np.inf),
            "curtailment": filters.window_range_flag(ws, 5.0, 25.0, pitch, -np.inf, thr)
            & filters.window_range_flag(p, -np.inf, 0.9 * RATED_KW, pitch, -np.inf, thr),
        }
        bad = np.zeros(len(g), bool)
        for f in flags.values():
            bad |= f.to_numpy(bool)
        kept = g.loc[~bad]
        curve = power_curve.IEC(kept["Ws_avg"], kept["P_avg"], bin_width=0.5, windspeed_start=0.0,
                                windspeed_end=30.0)
        lower = np.arange(0.0, 30.0, 0.5)
        n = np.array([int(((kept["Ws_avg"] >= a) & (kept["Ws_avg"] < a + 0.5)).sum()) for a in lower])
        power = curve(lower + 0.25)
        out[name] = {"records": int(len(g)), "duplicates_dropped": int(df["Wind_turbine_name"].eq(name).sum() - len(g)),
                     "flag_counts": {k: int(v.sum()) for k, v in flags.items()}, "kept": int(len(kept)),
                     "bins": {"lower_m_s": lower.tolist(), "n": n.tolist(),
                              "power_kw": [float(x) for x in power]}}
    return out


def main(argv=None) -> int:
    csv_path, out_path = (argv or sys.argv[1:])[:2]
    result = {"openoa_version": openoa.__version__, "pandas_version": pd.__version__,
              "function": "openoa.utils.power_curve.IEC(windspeed_col, power_col, bin_width=0.5, windspeed_start=0.0, "
                          "windspeed_end=30.0) evaluated at the bin centres (empty bins: OpenOA interpolates; compare "
                          "bins with n > 0)",
              "filters": "openoa.utils.filters.range_flag, unresponsive_flag(threshold=3), window_range_flag "
                         "(see benchmarks/openoa_reference.py)",
              "settings": SETTINGS, "data": csv_path.rsplit("/", 1)[-1], "turbines": reference(csv_path)}
    with open(out_path, "w") as fh:
        json.dump(result, fh, indent=1)
        fh.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
