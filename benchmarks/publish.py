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


def _git(*args: str) -> str:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, cwd=ROOT, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def commit() -> str:
    """The short hash of the checked-out commit ("unknown" outside a git checkout)."""
    return _git("rev-parse", "--short", "HEAD") or "unknown"


def process_start() -> float | None:
    """When this process started, in seconds since the epoch (Linux ``/proc``; None elsewhere)."""
    try:
        with open("/proc/self/stat") as fh:
            ticks = int(fh.read().rsplit(")", 1)[1].split()[19])       # field 22: starttime, clock ticks after boot
        with open("/proc/stat") as fh:
            boot = next(int(line.split()[1]) for line in fh if line.startswith("btime "))
        return boot + ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def run_commit() -> dict:
    """The commit the run started on, and the one checked out now if HEAD moved during the run.

    A battery of an hour can see commits land before it publishes; the figures belong to the code it
    started with: what HEAD was when this process started, read from HEAD's reflog (its entries carry
    the time HEAD moved). ``{"commit": ...}`` alone when HEAD did not move or the reflog cannot say;
    ``commit_at_publish`` beside it when it moved.
    """
    now = commit()
    start = process_start()
    if start is None or now == "unknown":
        return {"commit": now}
    then = now
    for line in _git("reflog", "--date=unix", "--format=%h %gd", "HEAD").splitlines():
        sha, _, ref = line.partition(" ")
        try:
            moved = int(ref[ref.index("{") + 1:ref.index("}")])
        except ValueError:
            break
        if moved <= start:
            then = sha
            break
    return {"commit": then} if then == now else {"commit": then, "commit_at_publish": now}


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
        json.dump({"date": datetime.date.today().isoformat(), **run_commit(), "command": command, **figures,
                   **extra}, fh, indent=1, default=str)
    os.replace(path + ".part", path)
    return path


def command_line() -> str:
    """The command that ran this benchmark, as a user would type it from the project root."""
    import sys

    script = os.path.relpath(os.path.abspath(sys.argv[0]), ROOT)
    return " ".join(["python", script, *sys.argv[1:]])


def publish_part(name: str, key: str, figures: dict, keep, tables, finish=None) -> str:
    """Publish one part (``key``) of a benchmark whose parts run in separate processes into
    ``docs/validation/data/<name>.json``, keeping the parts already there that ``keep(key, value)``
    accepts (so that parts run apart, or one that finished before a later one failed, are all
    published); each part keeps the command that made it. ``finish(merged)`` may add figures computed
    over the parts; ``tables(merged)`` is the page's Markdown. A lock serializes processes publishing
    the same file. Returns the path."""
    import fcntl
    import tempfile

    path = os.path.join(ROOT, "docs", "validation", "data", f"{name}.json")
    with open(os.path.join(tempfile.gettempdir(), f"calib_publish_{name}.lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        old = {}
        if os.path.exists(path):
            with open(path) as fh:
                old = {k: v for k, v in json.load(fh).items() if keep(k, v)}
        merged = {**old, key: {**figures, "command": command_line()}}
        if finish is not None:
            merged = finish(merged)
        return publish(name, merged, command_line(), tables(merged))
