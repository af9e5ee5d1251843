"""Soak, small: consecutive FMU evaluations keep resident memory bounded.

The fast variant of ``benchmarks/bench_soak.py`` (cheap steady window, quasi-steady
physics): 300 one-point evaluations through one FMU worker process; resident memory of
the calling process and of the FMU worker may grow less than 10 % after 100 warm-up
evaluations, with no failed evaluation. It runs in a fresh process: the pytest process
has run other tests and its RSS would hide a leak. The benchmark runs 2000 evaluations
and the same through Dask (``make bench``).
"""

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow
BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_soak.py"


def soak(tmp_path, *args):
    dest = tmp_path / "soak.json"
    done = subprocess.run([sys.executable, str(BENCH), "--fast", "--no-dask", "--json", str(dest), *args],
                          capture_output=True, text=True, timeout=300)
    assert dest.is_file(), done.stderr[-2000:]
    return done.returncode, json.loads(dest.read_text()), done.stdout


def test_300_fmu_evaluations_in_one_worker_keep_memory_bounded(tmp_path):
    code, res, out = soak(tmp_path, "--evaluations", "300", "--warmup", "100")
    print(out)
    assert res["one_worker_evaluations"] == 300 and res["one_worker_fmu_worker_processes"] == 1
    assert res["one_worker_non_ok_statuses"] == 0 and res["one_worker_worker_restarts"] == 0
    assert res["one_worker_driver_rss_growth_percent"] < 10.0
    assert res["one_worker_driver_fmu_rss_growth_percent"] < 10.0
    assert code == 0 and "error" not in res


def test_soak_check_fails_on_a_leak(tmp_path):
    """A deliberate leak of 1 MiB per evaluation in the calling process breaks the limit."""
    code, res, _ = soak(tmp_path, "--evaluations", "60", "--warmup", "20", "--leak-kib", "1024")
    assert code == 1
    assert res["one_worker_driver_rss_growth_percent"] > 10.0
    assert "calling process" in res["error"] and "limit 10 %" in res["error"]
