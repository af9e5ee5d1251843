"""Reader of the OpenFAST AeroDyn v15 airfoil (polar) file.

:func:`read_aerodyn_polar` reads ``NumTabs`` tables, each with Re, an optional
unsteady-aero block and ``NumAlf`` rows of Alpha, Cl, Cd[, Cm] (:data:`POLAR_COLUMNS`),
into an :class:`~calib.rotor.polar.Airfoil`.

Reference: OpenFAST documentation, AeroDyn v15 input files
(https://openfast.readthedocs.io, "AeroDyn Input Files").
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.rotor.input_file import (check_increasing, read_count, find_keyword, is_comment, is_number, read_number,
                                    read_lines, read_rows, tokens_of)
from calib.rotor.polar import MIN_POLAR_POINTS, Airfoil, PolarTable
from calib.rotor.viterna import densify_full_circle

POLAR_COLUMNS = ("Alpha", "Cl", "Cd", "Cm")
# keywords that start a new block of an airfoil file: a data table ends before them
_TABLE_KEYWORDS = {"re", "userprop", "ctrl", "incluadata", "numalf", "numtabs"}


def read_aerodyn_polar(path, name: str | None = None) -> Airfoil:
    """Read an AeroDyn v15 airfoil file with all its tables.

    Parameters
    ----------
    path : str or Path
        Airfoil file (AirfoilInfo v1.01 format).
    name : str, optional
        Airfoil name; default the file stem.

    Returns
    -------
    Airfoil
        One :class:`PolarTable` per table (``NumTabs``), Reynolds number converted from
        millions to absolute [-]; alpha [deg]; C_L, C_D, C_M [-] (C_M None when the file
        has no fourth column). ``InclUAdata`` blocks are skipped; ``@"file"`` values of
        NumCoords are tolerated (coordinates are not read). Full-circle tables with fewer
        than 4 rows (cylinders) are padded by linear interpolation.

    Raises
    ------
    InputError
        Missing or wrong ``NumTabs``/``NumAlf``, fewer rows than ``NumAlf``, non-numeric
        values, alpha not strictly increasing, fewer than 4 rows.
    """
    lines, src = read_lines(path)
    name = Path(path).stem if name is None else name
    i_tabs = find_keyword(lines, "NumTabs", 0)
    if i_tabs is None:
        raise InputError("keyword NumTabs (number of airfoil tables) not found", src, len(lines), "NumTabs")
    n_tabs = read_count(tokens_of(lines[i_tabs])[0], src, i_tabs + 1, "NumTabs")
    n_alf_lines = sum(1 for ln in lines[i_tabs:] if not is_comment(ln)
                      and len(tokens_of(ln)) >= 2 and tokens_of(ln)[1].lower() == "numalf")
    if n_alf_lines != n_tabs:
        raise InputError(f"NumTabs = {n_tabs} but the file has {n_alf_lines} tables (NumAlf lines)",
                         src, i_tabs + 1, "NumTabs")
    tables = []
    pos = i_tabs + 1
    for k in range(n_tabs):
        i_re = find_keyword(lines, "Re", pos, stop_keys=("NumAlf",))
        if i_re is None:
            raise InputError(f"table {k + 1}: no Re line before its NumAlf line", src, pos + 1, "Re")
        reynolds = read_number(tokens_of(lines[i_re])[0], src, i_re + 1, "Re") * 1e6
        if not (np.isfinite(reynolds) and reynolds > 0):
            raise InputError(f"expected a positive Reynolds number in millions, got {tokens_of(lines[i_re])[0]!r}",
                             src, i_re + 1, "Re")
        i_alf = find_keyword(lines, "NumAlf", i_re + 1, stop_keys=("Re",))
        if i_alf is None:
            raise InputError(f"table {k + 1}: no NumAlf line after Re", src, i_re + 1, "NumAlf")
        n_alf = read_count(tokens_of(lines[i_alf])[0], src, i_alf + 1, "NumAlf")
        values, row_lines, pos = read_rows(lines, i_alf + 1, n_alf, POLAR_COLUMNS, 3, src, "NumAlf",
                                            i_alf + 1, end_keywords=_TABLE_KEYWORDS)
        _check_no_extra_rows(lines, pos, src, n_alf, i_alf + 1)
        tables.append(_polar_table(values, row_lines, reynolds, src, i_alf + 1))
    return Airfoil(name, tuple(tables), notes=_header_notes(lines))


def _check_no_extra_rows(lines, pos, src, n_alf, count_line):
    """A numeric row right after the table means NumAlf is too small."""
    for i in range(pos, len(lines)):
        if is_comment(lines[i]):
            continue
        tok = tokens_of(lines[i])
        if len(tok) >= 3 and all(is_number(t) for t in tok[:3]):
            raise InputError(f"NumAlf = {n_alf} but another data row follows at line {i + 1}",
                             src, count_line, "NumAlf")
        return


def _polar_table(values, row_lines, reynolds, src, count_line) -> PolarTable:
    alpha, cl, cd = values[:, 0], values[:, 1], values[:, 2]
    cm = values[:, 3] if not np.any(np.isnan(values[:, 3])) else None
    check_increasing(alpha, row_lines, src, "Alpha", "Alpha")
    alpha, cl, cd, cm = densify_full_circle(alpha, cl, cd, cm)
    if alpha.size < MIN_POLAR_POINTS:
        raise InputError(f"a polar table needs at least {MIN_POLAR_POINTS} rows, this one has {alpha.size}",
                         src, count_line, "NumAlf")
    return PolarTable(alpha, cl, cd, cm, reynolds, source=src, first_line=int(row_lines[0]))


def _header_notes(lines) -> str:
    notes = []
    for ln in lines[1:6]:
        s = ln.strip().lstrip("!").strip()
        if s and not set(s) <= set("-=. "):
            notes.append(s)
    return " ".join(notes)

