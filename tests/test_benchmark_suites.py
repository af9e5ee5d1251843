"""`make bench` gives the speed figures in minutes; the statistical and soak studies run under
`make validate` (benchmarks/run_all.py --suite). Nothing is run here: only which module goes where."""

import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))

import run_all  # noqa: E402

SLOW = {"bench_coverage", "bench_soak", "bench_discrepancy", "bench_phase_vi", "bench_oof_battery", "bench_fmu_diagnosis",
        "bench_lifting_line_battery"}


def test_speed_suite_leaves_out_the_hour_long_studies():
    speed, validate = set(run_all.discover("speed")), set(run_all.discover("validate"))
    assert SLOW <= validate and not SLOW & speed
    assert {"bench_bem", "bench_ccblade", "bench_calibration", "bench_fmu_faults"} <= speed
    assert speed | validate == set(run_all.discover("all")) and not speed & validate
    assert run_all.discover("speed")[:4] == run_all.ORDER                       # the stated order first


@pytest.mark.parametrize("suite, file", [("speed", "results.json"), ("validate", "validation.json")])
def test_each_suite_writes_its_own_file(suite, file):
    assert run_all.OUT_FILES[suite] == file


def test_makefile_targets_call_the_suites():
    text = (BENCH.parent / "Makefile").read_text()
    assert "run_all.py --suite speed" in text.split("\nbench:")[1].split("\n\n")[0]
    assert "run_all.py --suite validate" in text.split("\nvalidate:")[1].split("\n\n")[0]


def test_every_benchmark_module_has_the_run_the_suites_call():
    """run_all calls each discovered module's run(): one without it fails `make bench` or `make validate`."""
    import ast

    for name in run_all.discover("all"):
        tree = ast.parse((BENCH / f"{name}.py").read_text())
        assert any(isinstance(n, ast.FunctionDef) and n.name == "run" for n in tree.body), f"{name}.py has no run()"
