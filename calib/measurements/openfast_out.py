"""OpenFAST text output (``.out``) read as a measurement table.

OpenFAST writes a few title lines, a channel-name row starting with ``Time``, a units row
(``(s)  (m/s)  (kW) ...``) and one row per output time step, the columns separated by tabs
(``TabDelim = True``) or blanks. :func:`calib.measurements.read_measurements` recognises such a
file from its content (:func:`channel_row`) and reads it with the helpers here: the OpenFAST
channel names are mapped to calib's (:data:`CHANNELS`), the units row gives the units, and the
time series is refused, averaged into one operating point or read row by row
(:func:`time_rows`, :func:`average`).

Channel mapping
---------------
OpenFAST names are compared case-insensitively; per calib name the first one present in the
file, in the order of :data:`CHANNELS`, is read and the others are named in a note. AeroDyn's
rotor loads come first because they are aerodynamic loads, what calib's model predicts;
ElastoDyn's are the structural loads at the low-speed shaft and the blade root (see
:data:`ELASTODYN_CAVEATS`).

The blade-root moments: calib's ``root_flap_moment`` is the out-of-plane moment of one blade
about its root (positive for a downwind normal force) and ``root_edge_moment`` the in-plane one
(positive for a tangential force in the direction of rotation). ElastoDyn's ``RootMyc1``
(alias ``RootMOoP1``, about the yc1 axis of the coned system) and ``RootMxc1`` (alias
``RootMIP1``, about xc1) are these moments with these signs (xc1 points downwind, yc1 toward
the trailing edge at zero pitch, zc1 along the pitch axis to the tip: a downwind force at
radius z gives z ẑ × x̂ = +ŷ, a force in the direction of rotation, −ŷ, gives +x̂).
``RootMyb1`` / ``RootMxb1`` (aliases ``RootMFlp1`` / ``RootMEdg1``) are the flapwise and
edgewise moments in blade axes, which turn with the pitch angle about −zc1: they equal the
out-of-plane and in-plane moments only at zero pitch and are not read.

Time series
-----------
calib expects one row per operating point (steady averages), an OpenFAST run is a time
series. By default a file with more than one time row is refused; ``time_series="mean"``
averages the rows from ``average_from`` [s] on into one operating point (drop the start-up
transient with it), ``time_series="rows"`` reads every row as a point.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from calib.errors import InputError

#: calib name -> OpenFAST channel names read for it, in order of preference (case-insensitive).
CHANNELS: dict[str, tuple[str, ...]] = {
    "wind_speed": ("Wind1VelX", "WindVxi", "uWind"),
    "rotor_speed": ("RotSpeed", "LSSTipVxa", "LSSTipVxs", "LSSTipV", "RtSpeed"),
    "pitch": ("BldPitch1", "BlPitch1", "B1Pitch"),
    "power": ("RtAeroPwr", "RotPwr", "LSShftPwr"),
    "thrust": ("RtAeroFxh", "RotThrust", "LSShftFxa", "LSShftFxs", "LSSGagFxa", "LSSGagFxs"),
    "torque": ("RtAeroMxh", "RotTorq", "LSShftMxa", "LSShftMxs", "LSSGagMxa", "LSSGagMxs", "LSShftTq"),
    "root_flap_moment": ("RootMyc1", "RootMOoP1"),
    "root_edge_moment": ("RootMxc1", "RootMIP1"),
}

#: What an ElastoDyn channel read for a calib channel carries besides the aerodynamic load.
ELASTODYN_CAVEATS: dict[str, str] = {
    "power": "the low-speed-shaft power equals the aerodynamic power only without rotor acceleration; "
             "AeroDyn's RtAeroPwr is the aerodynamic power",
    "torque": "the low-speed-shaft torque equals the aerodynamic torque only without rotor acceleration; "
              "AeroDyn's RtAeroMxh is the aerodynamic torque",
    "thrust": "the low-speed-shaft force also carries the rotor's weight along a tilted shaft and inertial "
              "loads; AeroDyn's RtAeroFxh is the aerodynamic thrust",
    "root_flap_moment": "a total root load, which also carries gravity (a steady part with shaft tilt) and "
                        "centrifugal loads where the blade leaves the rotor plane (precone, prebend, deflection)",
    "root_edge_moment": "a total root load, which also carries the blade's weight, a once-per-revolution part "
                        "that averages out only over whole revolutions",
}

#: Blade-axes root moments, not read: OpenFAST name (lower case) -> (calib name, channel to output instead).
BLADE_AXES: dict[str, tuple[str, str]] = {
    "rootmyb1": ("root_flap_moment", "RootMyc1"), "rootmflp1": ("root_flap_moment", "RootMyc1"),
    "rootmxb1": ("root_edge_moment", "RootMxc1"), "rootmedg1": ("root_edge_moment", "RootMxc1"),
}

_RANK = {name.lower(): (calib, rank) for calib, names in CHANNELS.items() for rank, name in enumerate(names)}
#: the channel-name row is looked for among the first lines only (OpenFAST writes about six title lines)
MAX_TITLE_LINES = 40
TIME_SERIES_MODES = (None, "mean", "rows")


def refuse_binary(path: Path) -> None:
    """Raise :class:`InputError` for an OpenFAST binary output file (``.outb``)."""
    if path.suffix.lower() == ".outb":
        raise InputError("OpenFAST binary output (.outb) is not read: write text output (OutFileFmt = 1 or 3 "
                         "in the .fst gives a tab-separated .out file) and read that", str(path))


def _first_token(text: str) -> str:
    parts = text.split(None, 1)
    return parts[0] if parts else ""


def channel_row(lines: Sequence[tuple[int, str]], path: Path) -> int | None:
    """Index in ``lines`` of the channel-name row of an OpenFAST text output, ``None`` if it is none.

    Parameters
    ----------
    lines : sequence of (line number, text)
        The file's non-blank lines.
    path : Path
        The file (its suffix counts).

    Notes
    -----
    The row's first name is ``Time`` and the next row's first cell ``(s)``; it is OpenFAST
    output when title lines come before it, the file is named ``.out`` or the row has an
    OpenFAST channel name of :data:`CHANNELS` (a logger table ``Time  wind_speed ...`` over
    ``(s)  (m/s) ...`` is read as a table with a units row).
    """
    for i in range(min(len(lines) - 1, MAX_TITLE_LINES)):
        if _first_token(lines[i][1]).lower() == "time" and _first_token(lines[i + 1][1]) == "(s)":
            if i > 0 or path.suffix.lower() == ".out" or any(t.lower() in _RANK for t in lines[i][1].split()):
                return i
            return None
    return None


@dataclass
class ChannelMap:
    """calib names of the columns of an OpenFAST output and what was not read.

    Attributes
    ----------
    names : list of str
        Per column, the calib name, or ``<OpenFAST column N: name>`` for a column not read.
    read : dict
        calib name -> OpenFAST name read for it.
    not_read : list of str
        The columns not read, with the reason where there is one.
    notes : list of str
    """

    names: list[str]
    read: dict[str, str] = field(default_factory=dict)
    not_read: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def map_channels(raw_names: Sequence[str]) -> ChannelMap:
    """Map the OpenFAST channel names of a channel-name row to calib names (see :data:`CHANNELS`)."""
    best: dict[str, tuple[int, int]] = {}                       # calib name -> (rank, column)
    for i, raw in enumerate(raw_names):
        hit = _RANK.get(raw.lower())
        if hit is not None and (hit[0] not in best or hit[1] < best[hit[0]][0]):
            best[hit[0]] = (hit[1], i)
    chosen = {i: calib for calib, (_, i) in best.items()}
    out = ChannelMap(names=[chosen.get(i, f"<OpenFAST column {i + 1}: {raw}>") for i, raw in enumerate(raw_names)])
    out.read = {calib: raw_names[i] for i, calib in sorted(chosen.items())}
    for i, raw in enumerate(raw_names):
        if i not in chosen and not (i == 0 and raw.lower() == "time"):      # Time is the time-series axis
            hit = _RANK.get(raw.lower())
            out.not_read.append(f"{raw} ({hit[0]} is read from {out.read[hit[0]]})" if hit else raw)
    out.notes = _mapping_notes(out, raw_names)
    return out


def _mapping_notes(m: ChannelMap, raw_names: Sequence[str]) -> list[str]:
    """The notes of a channel mapping: what is read, what not, and what an ElastoDyn channel carries."""
    notes = ["OpenFAST channels read: " + (", ".join(f"{raw} -> {calib}" for calib, raw in m.read.items())
                                           or "(none)")]
    if m.not_read:
        shown = m.not_read[:40]
        more = f" ... ({len(m.not_read)} in all)" if len(m.not_read) > 40 else ""
        notes.append(f"OpenFAST channels not read: {', '.join(shown)}{more}")
    lower = {r.lower() for r in raw_names}
    if m.read.get("wind_speed", "").lower() == "wind1velx":
        notes.append("wind_speed is InflowWind's Wind1VelX, the undisturbed wind at its first output point "
                     "(WindVxiList, WindVyiList, WindVziList): calib's is the hub-height free stream, so that "
                     "point should be the hub")
    for calib, raw in m.read.items():
        if calib in ELASTODYN_CAVEATS and raw.lower() not in ("rtaeropwr", "rtaerofxh", "rtaeromxh"):
            notes.append(f"{calib} is ElastoDyn's {raw}: {ELASTODYN_CAVEATS[calib]}")
    for key, (calib, instead) in BLADE_AXES.items():
        if key in lower and calib not in m.read:
            raw = next(r for r in raw_names if r.lower() == key)
            notes.append(f"{raw} is a blade-axes moment that turns with pitch, not calib's {calib} "
                         f"({'out-of-plane' if 'flap' in calib else 'in-plane'}); add {instead} to "
                         "ElastoDyn's OutList to measure it")
    return notes


def missing_hint(calib: str, raw_names: Sequence[str]) -> str:
    """Why a calib channel or condition is absent from an OpenFAST output, and what to output."""
    names = CHANNELS.get(calib)
    if not names:
        return ""
    lower = {r.lower() for r in raw_names}
    blade_axes = [k for k, (c, _) in BLADE_AXES.items() if c == calib and k in lower]
    extra = " (the blade-axes moment in the file turns with pitch and is not read)" if blade_axes else ""
    aliases = f" (or {', '.join(names[1:])})" if len(names) > 1 else ""
    return f"; OpenFAST channel {names[0]}{aliases} is read for it{extra}"


def time_rows(rows: list[tuple[int, list[str]]], raw_names: Sequence[str], time_series: str | None,
              average_from: float | None, src: str) -> tuple[list[tuple[int, list[str]]], dict[int, float], list[str]]:
    """The time rows to read, their times [s] by line, and notes; refuses a time series by default.

    Parameters
    ----------
    rows : list of (line number, cells)
        The data rows, the time in the first cell.
    raw_names : sequence of str
        The channel names (for messages).
    time_series : {None, "mean", "rows"}
        None: refuse more than one row; ``"mean"``: keep the rows from ``average_from`` on (they
        are averaged by :func:`average`); ``"rows"``: keep every row as a point.
    average_from : float or None
        Start of the averaging window [s] (``"mean"`` only; default: the first row).
    src : str
        The file, for messages.

    Raises
    ------
    InputError
        A time that is not a number, a time series without ``time_series``, no row in the window.
    """
    times = {}
    for line_no, cells in rows:
        try:
            t = float(cells[0]) if cells else float("nan")
        except ValueError:
            t = float("nan")
        if not np.isfinite(t):
            raise InputError(f"time {cells[0] if cells else ''!r} in column 1 '{raw_names[0]}' is not a finite "
                             "number [s]", src, line_no, field=raw_names[0])
        times[line_no] = t
    if len(rows) <= 1:
        return rows, times, []
    first, last = times[rows[0][0]], times[rows[-1][0]]
    if time_series is None:
        raise InputError(
            f"an OpenFAST time series ({len(rows)} time rows, t = {first:g} to {last:g} s): calib expects one row "
            "per operating point (steady averages); average each steady run into one row first, or read it with "
            "time_series='mean' (average_from=<end of the start-up transient> [s]) to average this file into one "
            "operating point, or time_series='rows' to read every time row as a point (in a workflow: "
            "[measurements] time_series = \"mean\", average_from = ...)", src, rows[0][0])
    if time_series == "rows":
        return rows, times, [f"time series read row by row (time_series='rows'): {len(rows)} points from "
                             f"t = {first:g} to {last:g} s, successive samples of one run, not independent records"]
    start = first if average_from is None else average_from
    kept = [(ln, c) for ln, c in rows if times[ln] >= start]
    if not kept:
        raise InputError(f"no time row at or after average_from = {average_from:g} s; the file's rows run from "
                         f"t = {first:g} to {last:g} s", src, rows[-1][0], field="average_from")
    dropped = len(rows) - len(kept)
    notes = [] if not dropped else [f"dropped the {dropped} time rows before average_from = {start:g} s"]
    if average_from is None:
        notes.append("averaged from the first time row (average_from not given): a start-up transient, if any, "
                     "is in the average")
    return kept, times, notes


def average(columns: dict[str, np.ndarray], times: np.ndarray, units: dict[str, str]) -> tuple[dict, str]:
    """Average each column over the time rows into one value; a note on the window.

    Parameters
    ----------
    columns : dict of ndarray, shape (n_rows,)
        Values per calib name, SI (``rotor_speed`` [rpm]).
    times : ndarray, shape (n_rows,)
        Time of each row [s].
    units : dict
        calib name -> SI unit (for the note).

    Returns
    -------
    dict of ndarray, shape (1,)
        The plain time average of each column (every row weighs the same: OpenFAST writes at a
        fixed step).
    str
        The window, the rotor revolutions in it (∫ Ω dt) and the standard deviation of each
        condition over it.
    """
    mean = {n: np.array([np.mean(v)]) for n, v in columns.items()}
    omega = columns["rotor_speed"] / 60.0                        # [rev/s]
    revolutions = float(np.sum(0.5 * (omega[1:] + omega[:-1]) * np.diff(times))) if times.size > 1 else 0.0
    spread = ", ".join(f"{n} {np.std(columns[n]):.3g} {units[n]}" for n in ("wind_speed", "rotor_speed", "pitch"))
    note = (f"time series averaged into one operating point: {times.size} rows, t = {times[0]:g} to "
            f"{times[-1]:g} s, {revolutions:.3g} rotor revolutions; standard deviation over the window: {spread}")
    if revolutions < 1.0:
        note += ("; fewer than one revolution: the once-per-revolution part of the root moments (the blade's "
                 "weight) does not average out")
    return mean, note
