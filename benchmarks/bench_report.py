"""Reporting time against calibration time on the wind-tunnel study (issue: reports that are fast).

Runs ``workflows/wind_tunnel_hub_loads.toml`` (calibration, figures, report) and then writes the
figures and the HTML report of its result again, timing both in this run. Target: figures +
report at most twice the calibration's wall time. A speed figure, so it lives here and not in
the test suite (a loaded machine moves it by tens of per cent).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

WIND_TUNNEL = Path(__file__).resolve().parents[1] / "workflows" / "wind_tunnel_hub_loads.toml"


def run() -> dict:
    from calib.report.figures import write_figures
    from calib.report.html import write_report
    from calib.workflow import run_workflow

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        [stage] = run_workflow(WIND_TUNNEL, tmp / "run", progress=False)
        t_run = time.perf_counter() - t0
        res = stage.result
        t0 = time.perf_counter()
        figures = write_figures(res, tmp / "report")
        write_report(tmp / "report" / "report.html", results={res.name: res}, figures={res.name: figures})
        t_report = time.perf_counter() - t0
    return {"calibration_s": res.provenance.wall_time, "figures_and_report_s": t_report, "whole_run_s": t_run,
            "report_to_calibration": t_report / res.provenance.wall_time, "target": "<= 2", "figures": len(figures)}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
