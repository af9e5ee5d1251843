import os
import subprocess
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
sys.path.insert(0, os.path.dirname(__file__))
ROOT = Path(__file__).resolve().parents[1]


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def fmus():
    """Both turbine FMUs, built from C source once per session (cached by source hash).

    A build failure fails the tests that need it: the build is part of the test set-up.
    """
    from calib.fmu.build import build_fmu
    return {v: build_fmu(v) for v in ("A", "B")}


@pytest.fixture(scope="session")
def docs_site(tmp_path_factory):
    """The documentation site, built once per session as ``make docs`` builds it (MkDocs in strict
    mode): ``(site directory, the finished build process)``. tests/test_docs.py asserts that it
    built; tests/test_browser_report.py opens its pages."""
    pytest.importorskip("mkdocs")
    pytest.importorskip("mkdocstrings")
    site = tmp_path_factory.mktemp("docs") / "site"
    build = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
                           capture_output=True, text=True, timeout=600, cwd=ROOT)
    return site, build


# ------------------------------------------------------------------ heap checks in FMU tests
#: Lines that mean a process's heap was corrupted or it crashed (glibc's malloc checks, signals
#: reported by Python's fault handler) or that a Python error escaped to stderr.
CRASH_LINES = ("corrupted double-linked list", "corrupted size vs. prev_size", "double free", "free(): invalid",
               "malloc(): ", "munmap_chunk(): invalid pointer", "Segmentation fault", "Fatal Python error",
               "Traceback (most recent call last)")
#: Test modules that load FMUs (in-process, in FMU worker processes or in executor workers).
FMU_MODULES = ("test_fmu_", "test_executors", "test_workflow_fmu_only", "test_conformance", "test_soak",
               "test_diagnose_seams", "test_discrepancy_scale_paths")
#: Tests whose FMU is made to crash on purpose (tests/data/fmu/FaultyRotor.py) may print a child's
#: traceback: only heap and signal lines count there.
EXPECTED_TRACEBACKS = ("test_fmu_faults",)
MALLOC_DEBUG = "/lib/x86_64-linux-gnu/libc_malloc_debug.so.0"


def _fmu_module(item) -> bool:
    return any(item.module.__name__.startswith(m) for m in FMU_MODULES) if item.module else False


@pytest.fixture(autouse=True)
def _glibc_heap_checker(request, monkeypatch):
    """Processes an FMU test starts run under glibc's heap checker (MALLOC_CHECK_=3 with the
    malloc debug library where this glibc needs it, and freed memory perturbed), so that a heap
    an FMU corrupts aborts with a message instead of passing silently."""
    if _fmu_module(request.node):
        monkeypatch.setenv("MALLOC_CHECK_", "3")
        monkeypatch.setenv("MALLOC_PERTURB_", "165")
        if os.path.exists(MALLOC_DEBUG):
            monkeypatch.setenv("LD_PRELOAD", MALLOC_DEBUG)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """An FMU test fails when its output (its own process's, and that of the processes it started,
    which inherit the captured descriptors) carries a crash line, even if its assertions passed."""
    outcome = yield
    rep = outcome.get_result()
    if not rep.passed or not _fmu_module(item):
        return
    lines = CRASH_LINES if not item.module.__name__.startswith(EXPECTED_TRACEBACKS) else CRASH_LINES[:-1]
    text = "\n".join(content for name, content in rep.sections
                     if name.endswith(rep.when) and ("stderr" in name or "stdout" in name))
    found = [ln for ln in text.splitlines() if any(c in ln for c in lines)]
    if found:
        rep.outcome = "failed"
        rep.longrepr = (f"a crash line on the output of this test or a process it started ({rep.when}): "
                        + " | ".join(found[:5]))
