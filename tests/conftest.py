import os
import sys

import matplotlib

matplotlib.use("Agg")
sys.path.insert(0, os.path.dirname(__file__))


import pytest  # noqa: E402


@pytest.fixture(scope="session")
def fmus():
    """Both turbine FMUs, built from C source once per session (cached by source hash).

    A build failure fails the tests that need it: the build is part of the test set-up.
    """
    from calib.fmu.build import build_fmu
    return {v: build_fmu(v) for v in ("A", "B")}
