"""Reader of the OpenFAST AeroDyn v15 blade definition file.

:func:`read_aerodyn_blade` reads the ``NumBlNds`` rows of BlSpn, BlCrvAC, BlSwpAC, BlCrvAng,
BlTwist, BlChord, BlAFID (:data:`BLADE_COLUMNS`).

Reference: OpenFAST documentation, AeroDyn v15 input files
(https://openfast.readthedocs.io, "AeroDyn Input Files").
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.rotor.input_file import check_increasing, read_count, find_keyword, read_lines, read_rows, tokens_of

BLADE_COLUMNS = ("BlSpn", "BlCrvAC", "BlSwpAC", "BlCrvAng", "BlTwist", "BlChord", "BlAFID")
_BLADE_KEYS = {"BlSpn": "span", "BlCrvAC": "curve_ac", "BlSwpAC": "sweep_ac", "BlCrvAng": "curve_angle",
               "BlTwist": "twist", "BlChord": "chord", "BlAFID": "af_id"}
_MAX_AFID = 2 ** 31 - 1  # BlAFID indexes AFNames; larger values do not fit an integer index


def read_aerodyn_blade(path) -> dict:
    """Read an AeroDyn v15 blade definition file.

    Exactly ``NumBlNds`` rows are read; anything after them is ignored (the NREL 5-MW
    file carries a 20th row after a comment while ``NumBlNds = 19``, as AeroDyn reads it).
    Extra columns (BlCb, BlCenBn, BlCenBt) are ignored.

    Parameters
    ----------
    path : str or Path
        The blade file.

    Returns
    -------
    dict
        ``span`` BlSpn, distance from the blade root along the pitch axis [m];
        ``curve_ac`` BlCrvAC, out-of-plane offset of the aerodynamic centre, positive
        downwind [m]; ``sweep_ac`` BlSwpAC, in-plane offset [m]; ``curve_angle`` BlCrvAng
        [deg]; ``twist`` BlTwist [deg]; ``chord`` BlChord [m]; ``af_id`` BlAFID, 1-based
        airfoil index as in the file (int); ``line`` the 1-based line of each node;
        ``source`` the file name. Arrays have shape (NumBlNds,).

    Raises
    ------
    InputError
        Missing ``NumBlNds`` or column, fewer rows than ``NumBlNds``, non-numeric values,
        BlSpn negative or not increasing, BlChord <= 0, BlAFID not a positive integer.
    """
    lines, src = read_lines(path)
    i_n = find_keyword(lines, "NumBlNds", 0)
    i_head = next((i for i, ln in enumerate(lines) if "BlSpn" in tokens_of(ln)), None)
    if i_n is None or (i_head is not None and i_head < i_n):
        where = i_head + 1 if i_head is not None else len(lines)
        raise InputError("keyword NumBlNds (number of blade nodes) not found before the node table",
                         src, where, "NumBlNds")
    n_nodes = read_count(tokens_of(lines[i_n])[0], src, i_n + 1, "NumBlNds", minimum=2)
    i_head = next((i for i in range(i_n + 1, len(lines)) if "BlSpn" in tokens_of(lines[i])), None)
    if i_head is None:
        raise InputError("column header line (BlSpn BlCrvAC ...) not found after NumBlNds",
                         src, i_n + 1, "BlSpn")
    header = tokens_of(lines[i_head])
    missing = [c for c in BLADE_COLUMNS if c not in header]
    if missing:
        raise InputError(f"column {missing[0]} missing from the header {header}", src, i_head + 1, missing[0])
    # the units line follows the header; rows start after it
    values, row_lines, _ = read_rows(lines, i_head + 2, n_nodes, tuple(header), len(header), src,
                                      "NumBlNds", i_n + 1)
    out = {_BLADE_KEYS[c]: values[:, header.index(c)] for c in BLADE_COLUMNS}
    ids = out["af_id"]
    bad = np.flatnonzero((ids != np.round(ids)) | (ids < 1) | (ids > _MAX_AFID))
    if bad.size:
        raise InputError(f"airfoil id must be a positive integer (an index into AFNames, at most {_MAX_AFID}), "
                         f"got {ids[bad[0]]:g}", src, int(row_lines[bad[0]]), "BlAFID")
    bad = np.flatnonzero(out["chord"] <= 0)
    if bad.size:
        raise InputError(f"chord must be > 0, got {out['chord'][bad[0]]:g} m",
                         src, int(row_lines[bad[0]]), "BlChord")
    if out["span"][0] < 0:
        raise InputError(f"BlSpn is measured from the blade root and must be >= 0, got "
                         f"{out['span'][0]:g} m", src, int(row_lines[0]), "BlSpn")
    check_increasing(out["span"], row_lines, src, "BlSpn", "BlSpn")
    out["af_id"] = ids.astype(int)
    out["line"] = row_lines
    out["source"] = src
    return out

