"""Figures and report of the wind-tunnel study take at most twice the calibration's wall time."""

import time
from pathlib import Path

import pytest

from calib.report.figures import write_figures
from calib.report.html import write_report
from calib.workflow import run_workflow

WIND_TUNNEL = Path(__file__).resolve().parents[1] / "workflows" / "wind_tunnel_hub_loads.toml"


@pytest.mark.slow
def test_reporting_takes_at_most_twice_the_calibration(tmp_path):
    [stage] = run_workflow(WIND_TUNNEL, tmp_path / "run", progress=False)
    res = stage.result
    t0 = time.perf_counter()
    figures = write_figures(res, tmp_path / "report")
    write_report(tmp_path / "report" / "report.html", results={res.name: res}, figures={res.name: figures})
    t_report = time.perf_counter() - t0
    print(f"\nwind tunnel: calibration {res.wall_time:.2f} s (estimation loop, without covariances and "
          f"bands), figures + report {t_report:.2f} s, ratio {t_report / res.wall_time:.2f}")
    assert len(figures) >= 6
    assert t_report <= 2.0 * res.wall_time
