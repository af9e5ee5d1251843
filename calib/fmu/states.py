"""Settled FMU states in a file: written with the build's identity, refused for another build.

Format: one JSON header line (``magic``, the FMU's GUID / instantiation token and SHA-256, its path,
the operating conditions, the size of each point's serialized state) followed by the states' bytes
back to back. A settled state lets a later run of the same build skip settling.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from calib.errors import InputError
from calib.types import OperatingConditions

STATE_MAGIC = "calib-fmu-settled-states/1"


def write_states(path, states: list, conditions: OperatingConditions, guid: str, sha256: str, fmu_path) -> Path:
    """Write ``states`` (bytes or None per point) at ``conditions``, atomically; returns the path."""
    path = Path(path)
    header = {"magic": STATE_MAGIC, "guid": guid, "fmu_sha256": sha256, "fmu": str(fmu_path),
              "conditions": {k: v.tolist() for k, v in conditions.as_dict().items()},
              "sizes": [0 if s is None else len(s) for s in states]}
    tmp = path.with_suffix(path.suffix + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(json.dumps(header).encode() + b"\n")
        for s in states:
            if s is not None:
                fh.write(s)
    os.replace(tmp, path)
    return path


def read_states(path, guid: str, sha256: str, fmu_name: str) -> tuple[list, OperatingConditions]:
    """The states and conditions of a :func:`write_states` file written by the build ``guid`` / ``sha256``.

    Raises
    ------
    InputError
        Not a state file, a state saved by another build (named: its GUID and file), or a file whose
        length disagrees with its header.
    """
    path = Path(path)
    src = str(path)
    try:
        raw = path.read_bytes()
        head, _, body = raw.partition(b"\n")
        header = json.loads(head)
    except (OSError, ValueError):
        raise InputError("not a calib FMU state file", src) from None
    if not isinstance(header, dict) or header.get("magic") != STATE_MAGIC:
        raise InputError(f"not a calib FMU state file (expected magic {STATE_MAGIC!r})", src, field="magic")
    if header.get("guid") != guid or header.get("fmu_sha256") != sha256:
        raise InputError(f"state from another build: saved by the FMU with GUID {header.get('guid')} "
                         f"({header.get('fmu')}), this FMU {fmu_name} has GUID {guid}; settle "
                         "again with this build", src, field="guid")
    states, offset = [], 0
    for size in header["sizes"]:
        states.append(body[offset:offset + size] if size else None)
        offset += size
    if offset != len(body):
        raise InputError(f"state file truncated or padded ({len(body)} bytes of states, header says {offset})",
                         src, field="sizes")
    return states, OperatingConditions(**header["conditions"])
