"""Test FMUs from another exporter: PythonFMU's command line on a slave in tests/data/fmu/."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

DATA = Path(__file__).parent / "data" / "fmu"


def export_fmu(slave: str, out: Path) -> Path:
    """Build ``tests/data/fmu/<slave>.py`` into ``out/<slave>.fmu`` (state handling and
    serialization on); a missing or failing PythonFMU fails the calling test with its stderr."""
    cmd = [sys.executable, "-m", "pythonfmu", "build", "-f", str(DATA / f"{slave}.py"), "--handle-state",
           "--serialize-state", "-d", str(out)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return Path(out) / f"{slave}.fmu"
