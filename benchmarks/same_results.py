"""Same results before and after a refactoring: every shipped workflow, ``calib demo`` and Phase VI.

``python benchmarks/same_results.py snapshot DIR`` runs ``calib demo`` and ``calib run`` of every
workflow in ``workflows/`` (Phase VI included) into ``DIR``; ``python benchmarks/same_results.py
compare OLD NEW`` compares two snapshots: every number of every ``result.json``, ``result.npz``,
``diagnosis.json``, ``validation.json`` and ``summary.json`` (timings, dates, versions and paths
left out; ``history/`` too: a cache keyed by hashes that include the checkout's paths) within ``--rtol`` (default 1e-10) relative, and the key sets (a name that disappeared or
appeared is listed); a schema-3 result (fields under their parts) compares field by field with a
schema-2 snapshot. Exit status 1 when anything differs. A development tool for the architecture
steps, not a test: its baseline is the code's own output.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SKIP = ("seconds", "time", "wall", "versions", "date", "path", "file", "dir", "elapsed", "timeout", "hash",
        "sha256", "inputs", "source", "command", "log", "median healthy")


def snapshot(out: Path) -> int:
    out.mkdir(parents=True, exist_ok=True)
    (out / "checkout.txt").write_text(str(ROOT))     # so that paths compare across checkouts
    calib = str(Path(sys.executable).with_name("calib"))
    runs = [("demo", [calib, "demo", "--out", str(out / "demo")])]
    runs += [(p.stem, [calib, "run", str(p), "--out", str(out / p.stem), "-q", "--no-history"])
             for p in sorted((ROOT / "workflows").glob("*.toml"))]
    status = 0
    for name, cmd in runs:
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
        print(f"[same results] {name}: exit {proc.returncode}", flush=True)
        if proc.returncode:
            print(proc.stderr[-2000:])
            status = 1
    return status


def _skip(key: str) -> bool:
    k = key.lower()
    return any(s in k for s in SKIP)


def _leaves(x, prefix=""):
    """The numeric leaves of a JSON document, by dotted key path (skipped keys left out)."""
    if isinstance(x, dict):
        for k, v in x.items():
            if not _skip(str(k)):
                yield from _leaves(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            yield from _leaves(v, f"{prefix}[{i}]")
    elif isinstance(x, bool) or x is None or isinstance(x, str):
        yield prefix, x
    elif isinstance(x, (int, float)):
        yield prefix, float(x)


#: The parts a schema-3 ``result.json`` holds its fields under (``result.npz``: ``part.field``).
RESULT_PARTS = ("estimate", "identifiability", "uncertainty", "fit", "provenance")


def _as_flat_result(doc: dict) -> dict:
    """A ``result.json`` with every part's fields under their own names, as schema 2 wrote them, so
    that snapshots on both sides of the schema change compare field by field."""
    out = {k: v for k, v in doc.items() if k not in RESULT_PARTS and k != "schema_version"}
    for part in RESULT_PARTS:
        out.update(doc.get(part, {}))
    return out


def _flat_array_name(name: str) -> str:
    """``estimate.p_hat`` -> ``p_hat`` (schema 3's array names as schema 2's)."""
    part, _, field = name.partition(".")
    return field if part in RESULT_PARTS and field else name


def _close(a, b, rtol: float) -> bool:
    """Equal within ``rtol`` relative (of the value, or of 1e-6 of the array's largest finite value), with
    NaN and infinities where the other has the same."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return False
    finite = np.isfinite(a) & np.isfinite(b)
    if not np.array_equal(a[~finite], b[~finite], equal_nan=True):
        return False
    if not finite.any():
        return True
    x, y = a[finite], b[finite]
    scale = float(np.max(np.abs(x)))
    return bool(np.all(np.abs(x - y) <= rtol * np.maximum(np.abs(x), 1e-6 * scale)))


def compare(old: Path, new: Path, rtol: float) -> int:
    problems, checked = [], 0
    roots = [(p / "checkout.txt").read_text() if (p / "checkout.txt").is_file() else "\0" for p in (old, new)]
    for f in sorted(old.rglob("*")):
        rel = f.relative_to(old)
        if "history" in rel.parts:       # the run's cache of model calls, keyed by hashes that include paths
            continue
        g = new / rel
        if f.suffix == ".json" and f.name in ("result.json", "diagnosis.json", "validation.json", "summary.json"):
            if not g.exists():
                problems.append(f"{rel}: missing in the new snapshot")
                continue
            docs = [json.loads(h.read_text()) for h in (f, g)]
            if f.name == "result.json":
                docs = [_as_flat_result(d) for d in docs]
            a, b = dict(_leaves(docs[0])), dict(_leaves(docs[1]))
            for k in sorted(set(a) ^ set(b)):
                problems.append(f"{rel}: key {k} only in the {'old' if k in a else 'new'} snapshot")
            for k in sorted(set(a) & set(b)):
                checked += 1
                x, y = a[k], b[k]
                if isinstance(x, float) and isinstance(y, float):
                    if not _close(x, y, rtol):
                        problems.append(f"{rel}: {k} {x!r} -> {y!r}")
                elif x != y and not (isinstance(x, str) and isinstance(y, str)
                                     and x.replace(roots[0], "<checkout>") == y.replace(roots[1], "<checkout>")):
                    problems.append(f"{rel}: {k} {x!r} -> {y!r}")
        elif f.suffix == ".npz":
            if not g.exists():
                problems.append(f"{rel}: missing in the new snapshot")
                continue
            with np.load(f, allow_pickle=False) as za, np.load(g, allow_pickle=False) as zb:
                xa = {_flat_array_name(k): za[k] for k in za.files}
                xb = {_flat_array_name(k): zb[k] for k in zb.files}
            for k in sorted(set(xa) ^ set(xb)):
                problems.append(f"{rel}: array {k} only in the {'old' if k in xa else 'new'} snapshot")
            for k in sorted(set(xa) & set(xb)):
                checked += 1
                if xa[k].dtype.kind in "fiub" and xb[k].dtype.kind in "fiub":
                    if not _close(xa[k], xb[k], rtol):
                        problems.append(f"{rel}: array {k} differs beyond rtol {rtol:g}")
                elif not np.array_equal(xa[k], xb[k]):
                    problems.append(f"{rel}: array {k} differs")
    print(f"[same results] {checked} numbers and arrays compared at rtol {rtol:g}: {len(problems)} differ")
    for p in problems[:200]:
        print("  " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("snapshot")
    s.add_argument("dir", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("old", type=Path)
    c.add_argument("new", type=Path)
    c.add_argument("--rtol", type=float, default=1e-10)
    args = ap.parse_args()
    sys.exit(snapshot(args.dir) if args.cmd == "snapshot" else compare(args.old, args.new, args.rtol))
