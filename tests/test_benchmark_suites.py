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


def test_published_figures_carry_the_commit_the_run_started_on(monkeypatch):
    """A battery that runs for an hour while commits land is stamped with HEAD at its start (reflog), and
    says which commit was checked out when it published."""
    import publish

    reflog = "ccc3333 HEAD@{3000}\nbbb2222 HEAD@{2000}\naaa1111 HEAD@{1000}"
    monkeypatch.setattr(publish, "_git", lambda *a: "ccc3333" if a[0] == "rev-parse" else reflog)
    monkeypatch.setattr(publish, "process_start", lambda: 2500.0)
    assert publish.run_commit() == {"commit": "bbb2222", "commit_at_publish": "ccc3333"}
    monkeypatch.setattr(publish, "process_start", lambda: 3500.0)
    assert publish.run_commit() == {"commit": "ccc3333"}
    monkeypatch.setattr(publish, "process_start", lambda: None)
    assert publish.run_commit() == {"commit": "ccc3333"}


def test_this_process_started_before_now():
    import time

    import publish

    start = publish.process_start()
    if start is None:
        pytest.skip("no /proc: the start time is unknown and the stamp falls back to HEAD")
    assert time.time() - 7 * 86400 < start <= time.time() + 1


def test_parts_published_apart_are_all_kept(monkeypatch, tmp_path):
    """publish_part: a benchmark's parts run in separate processes all reach the file, the parts ``keep``
    refuses are dropped, ``finish`` sees every part, each part keeps its command."""
    import json

    import publish

    monkeypatch.setattr(publish, "ROOT", str(tmp_path))
    monkeypatch.setattr(publish, "run_commit", lambda: {"commit": "abc1234"})
    monkeypatch.setattr(publish, "command_line", lambda: "python benchmarks/bench_x.py")

    def tables(merged):
        return "| " + " | ".join(sorted(k for k in merged if k.startswith("part"))) + " |"

    def finish(merged):
        return {**merged, "total": sum(v["n"] for k, v in merged.items() if k.startswith("part"))}

    keep = lambda k, v: k.startswith("part")                                       # noqa: E731
    publish.publish_part("x", "part_a", {"n": 1}, keep, tables, finish)
    path = publish.publish_part("x", "part_b", {"n": 2}, keep, tables, finish)
    data = json.loads(open(path).read())
    assert data["part_a"] == {"n": 1, "command": "python benchmarks/bench_x.py"} and data["part_b"]["n"] == 2
    assert data["total"] == 3 and data["markdown"] == "| part_a | part_b |" and data["commit"] == "abc1234"
    path = publish.publish_part("x", "part_c", {"n": 4}, lambda k, v: k == "part_b", tables)
    data = json.loads(open(path).read())
    assert "part_a" not in data and "total" not in data and data["part_c"]["n"] == 4
