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


def publish(name: str, figures: dict, command: str) -> str:
    """Write ``figures`` with the date, the commit and ``command`` to ``docs/validation/data/<name>.json``;
    returns the path."""
    path = os.path.join(ROOT, "docs", "validation", "data", f"{name}.json")
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        json.dump({"date": datetime.date.today().isoformat(), "commit": commit(), "command": command, **figures},
                  fh, indent=1)
    return path
