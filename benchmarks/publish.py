"""Benchmark figures published for the documentation: ``docs/validation/data/NAME.json``.

Each publishing benchmark writes its figures there with the date, the commit and the command, and
the documentation's MkDocs hook (``docs/hooks.py``) renders them into the validation pages, so the
pages' tables come from a run and say which.
"""

from __future__ import annotations

import datetime
import json
import os
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def commit() -> str:
    """The short hash of the checked-out commit ("unknown" outside a git checkout)."""
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=ROOT,
                             timeout=10).stdout.strip()
    except OSError:
        out = ""
    return out or "unknown"


def publish(name: str, figures: dict, command: str, markdown: str | None = None) -> str:
    """Write ``figures`` with the date, the commit and ``command`` to ``docs/validation/data/<name>.json``;
    returns the path.

    ``markdown``: the benchmark's own tables of these figures; the page shows them under the run's date,
    commit and command (a benchmark that needs no page-specific layout publishes its tables this way).
    """
    path = os.path.join(ROOT, "docs", "validation", "data", f"{name}.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    extra = {} if markdown is None else {"markdown": markdown}
    with open(path + ".part", "w") as fh:
        json.dump({"date": datetime.date.today().isoformat(), "commit": commit(), "command": command, **figures,
                   **extra}, fh, indent=1, default=str)
    os.replace(path + ".part", path)
    return path


def command_line() -> str:
    """The command that ran this benchmark, as a user would type it from the project root."""
    import sys

    script = os.path.relpath(os.path.abspath(sys.argv[0]), ROOT)
    return " ".join(["python", script, *sys.argv[1:]])
