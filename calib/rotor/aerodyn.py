"""Readers for OpenFAST AeroDyn v15 input files.

- :func:`read_aerodyn_blade`: blade definition file (``NumBlNds`` rows of BlSpn, BlCrvAC,
  BlSwpAC, BlCrvAng, BlTwist, BlChord, BlAFID).
- :func:`read_aerodyn_polar`: airfoil file (``NumTabs`` tables, each with Re, optional
  unsteady-aero block and ``NumAlf`` rows of Alpha, Cl, Cd[, Cm]).
- :func:`read_aerodyn_afnames`: the ``AFNames`` list of the AeroDyn main input.
- :func:`read_aerodyn_main`: the BEM set-up, fluid and file names of the AeroDyn main input,
  both field generations (:class:`AeroDynMain`).
- :func:`rotor_from_aerodyn`: a :class:`~calib.rotor.geometry.Rotor` from these files.
- :class:`InputFileValues`: the ``value  Keyword  - description`` lines of any OpenFAST input
  file, looked up by keyword (also used by :mod:`calib.rotor.openfast`).

AeroDyn main-file field generations (both read):

1. OpenFAST up to 3.5: ``WakeMod`` {0 none, 1 BEMT, 2 DBEMT, 3 OLAF} and ``AFAeroMod``
   {1 steady, 2 Beddoes-Leishman with ``UAMod``};
2. OpenFAST 4: ``Wake_Mod`` {0 none, 1 BEMT, 3 OLAF} (dynamic BEMT moved to ``DBEMT_Mod``)
   and ``UA_Mod`` {0 quasi-steady, 2..7 unsteady models}.

Every error is an :class:`~calib.errors.InputError` naming the file, the 1-based line
and the field (column or keyword as spelled in the file).

Reference: OpenFAST documentation, AeroDyn v15 input files
(https://openfast.readthedocs.io, "AeroDyn Input Files").
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

import numpy as np

from calib.errors import InputError
from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import MIN_POLAR_POINTS, Airfoil, PolarTable
from calib.rotor.viterna import densify_full_circle

BLADE_COLUMNS = ("BlSpn", "BlCrvAC", "BlSwpAC", "BlCrvAng", "BlTwist", "BlChord", "BlAFID")
POLAR_COLUMNS = ("Alpha", "Cl", "Cd", "Cm")
_BLADE_KEYS = {"BlSpn": "span", "BlCrvAC": "curve_ac", "BlSwpAC": "sweep_ac", "BlCrvAng": "curve_angle",
               "BlTwist": "twist", "BlChord": "chord", "BlAFID": "af_id"}
# keywords that start a new block of an airfoil file: a data table ends before them
_TABLE_KEYWORDS = {"re", "userprop", "ctrl", "incluadata", "numalf", "numtabs"}
_TOKEN = re.compile(r'"([^"]*)"|(\S+)')
_LINE_BREAK = re.compile(r"\r\n|\r|\n")
_MAX_AFID = 2 ** 31 - 1  # BlAFID indexes AFNames; larger values do not fit an integer index


# ---------------------------------------------------------------- low-level helpers
def _read_lines(path) -> tuple[list[str], str]:
    path = Path(path)
    src = str(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise InputError("file not found", src) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc})", src) from None
    # lines end at \n, \r\n or \r only, as OpenFAST reads them: str.splitlines also splits at form
    # feeds, \x85 and U+2028, and every later line number in a message would be off
    lines = _LINE_BREAK.split(text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines, src


def _is_comment(line: str) -> bool:
    s = line.strip()
    return not s or s.startswith("!") or s.startswith("#")


def _tokens(line: str) -> list[str]:
    """Whitespace tokens before an inline ``!`` comment."""
    return line.split("!", 1)[0].split()


def _find_keyword(lines, key: str, start: int, stop_keys=()) -> int | None:
    """Index of the first line (>= start) whose second token is ``key``.

    The search stops (returns None) at a line whose second token is in ``stop_keys``.
    """
    key = key.lower()
    stops = {k.lower() for k in stop_keys}
    for i in range(start, len(lines)):
        if _is_comment(lines[i]):
            continue
        tok = _tokens(lines[i])
        if len(tok) >= 2:
            word = tok[1].lower()
            if word == key:
                return i
            if word in stops:
                return None
    return None


def _number(text: str, src: str, line: int, field: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"expected a number, got {text!r}", src, line, field) from None
    if not np.isfinite(value):
        raise InputError(f"expected a finite number, got {text!r}", src, line, field)
    return value


def _count(text: str, src: str, line: int, field: str, minimum: int = 1) -> int:
    try:
        value = int(text)
    except ValueError:
        raise InputError(f"expected an integer count, got {text!r}", src, line, field) from None
    if value < minimum:
        raise InputError(f"must be >= {minimum}, got {value}", src, line, field)
    return value


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_rows(lines, start: int, n_rows: int, names, n_required: int, src: str,
               count_field: str, count_line: int, end_keywords=frozenset()):
    """Read ``n_rows`` numeric rows from ``lines[start:]``, skipping comment lines.

    Returns (values (n_rows, n_cols) with NaN for absent optional columns, line numbers
    (1-based), index of the line after the last row).
    """
    rows, row_lines = [], []
    i = start
    while len(rows) < n_rows and i < len(lines):
        line = lines[i]
        i += 1
        if _is_comment(line):
            continue
        tok = _tokens(line)
        if len(tok) >= 2 and tok[1].lower() in end_keywords and not _is_number(tok[1]):
            i -= 1
            break
        if len(tok) < n_required:
            raise InputError(f"expected {n_required} columns ({', '.join(names[:n_required])}), "
                             f"found {len(tok)}", src, i, names[len(tok)])
        vals = [_number(t, src, i, names[k]) for k, t in enumerate(tok[:len(names)])]
        vals += [np.nan] * (len(names) - len(vals))
        rows.append(vals)
        row_lines.append(i)
    if len(rows) < n_rows:
        raise InputError(f"{count_field} = {n_rows} but only {len(rows)} data rows follow "
                         f"(table ends at line {i})", src, count_line, count_field)
    return np.array(rows, dtype=float).reshape(n_rows, len(names)), np.array(row_lines), i


def _check_increasing(values, row_lines, src, field, what):
    bad = np.flatnonzero(np.diff(values) <= 0)
    if bad.size:
        k = bad[0] + 1
        raise InputError(f"{what} must be strictly increasing: {values[k]:g} follows {values[k - 1]:g}",
                         src, int(row_lines[k]), field)


# ---------------------------------------------------------------- blade file
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
    lines, src = _read_lines(path)
    i_n = _find_keyword(lines, "NumBlNds", 0)
    i_head = next((i for i, ln in enumerate(lines) if "BlSpn" in _tokens(ln)), None)
    if i_n is None or (i_head is not None and i_head < i_n):
        where = i_head + 1 if i_head is not None else len(lines)
        raise InputError("keyword NumBlNds (number of blade nodes) not found before the node table",
                         src, where, "NumBlNds")
    n_nodes = _count(_tokens(lines[i_n])[0], src, i_n + 1, "NumBlNds", minimum=2)
    i_head = next((i for i in range(i_n + 1, len(lines)) if "BlSpn" in _tokens(lines[i])), None)
    if i_head is None:
        raise InputError("column header line (BlSpn BlCrvAC ...) not found after NumBlNds",
                         src, i_n + 1, "BlSpn")
    header = _tokens(lines[i_head])
    missing = [c for c in BLADE_COLUMNS if c not in header]
    if missing:
        raise InputError(f"column {missing[0]} missing from the header {header}", src, i_head + 1, missing[0])
    # the units line follows the header; rows start after it
    values, row_lines, _ = _read_rows(lines, i_head + 2, n_nodes, tuple(header), len(header), src,
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
    _check_increasing(out["span"], row_lines, src, "BlSpn", "BlSpn")
    out["af_id"] = ids.astype(int)
    out["line"] = row_lines
    out["source"] = src
    return out


# ---------------------------------------------------------------- airfoil file
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
    lines, src = _read_lines(path)
    name = Path(path).stem if name is None else name
    i_tabs = _find_keyword(lines, "NumTabs", 0)
    if i_tabs is None:
        raise InputError("keyword NumTabs (number of airfoil tables) not found", src, len(lines), "NumTabs")
    n_tabs = _count(_tokens(lines[i_tabs])[0], src, i_tabs + 1, "NumTabs")
    n_alf_lines = sum(1 for ln in lines[i_tabs:] if not _is_comment(ln)
                      and len(_tokens(ln)) >= 2 and _tokens(ln)[1].lower() == "numalf")
    if n_alf_lines != n_tabs:
        raise InputError(f"NumTabs = {n_tabs} but the file has {n_alf_lines} tables (NumAlf lines)",
                         src, i_tabs + 1, "NumTabs")
    tables = []
    pos = i_tabs + 1
    for k in range(n_tabs):
        i_re = _find_keyword(lines, "Re", pos, stop_keys=("NumAlf",))
        if i_re is None:
            raise InputError(f"table {k + 1}: no Re line before its NumAlf line", src, pos + 1, "Re")
        reynolds = _number(_tokens(lines[i_re])[0], src, i_re + 1, "Re") * 1e6
        if not (np.isfinite(reynolds) and reynolds > 0):
            raise InputError(f"expected a positive Reynolds number in millions, got {_tokens(lines[i_re])[0]!r}",
                             src, i_re + 1, "Re")
        i_alf = _find_keyword(lines, "NumAlf", i_re + 1, stop_keys=("Re",))
        if i_alf is None:
            raise InputError(f"table {k + 1}: no NumAlf line after Re", src, i_re + 1, "NumAlf")
        n_alf = _count(_tokens(lines[i_alf])[0], src, i_alf + 1, "NumAlf")
        values, row_lines, pos = _read_rows(lines, i_alf + 1, n_alf, POLAR_COLUMNS, 3, src, "NumAlf",
                                            i_alf + 1, end_keywords=_TABLE_KEYWORDS)
        _check_no_extra_rows(lines, pos, src, n_alf, i_alf + 1)
        tables.append(_polar_table(values, row_lines, reynolds, src, i_alf + 1))
    return Airfoil(name, tuple(tables), notes=_header_notes(lines))


def _check_no_extra_rows(lines, pos, src, n_alf, count_line):
    """A numeric row right after the table means NumAlf is too small."""
    for i in range(pos, len(lines)):
        if _is_comment(lines[i]):
            continue
        tok = _tokens(lines[i])
        if len(tok) >= 3 and all(_is_number(t) for t in tok[:3]):
            raise InputError(f"NumAlf = {n_alf} but another data row follows at line {i + 1}",
                             src, count_line, "NumAlf")
        return


def _polar_table(values, row_lines, reynolds, src, count_line) -> PolarTable:
    alpha, cl, cd = values[:, 0], values[:, 1], values[:, 2]
    cm = values[:, 3] if not np.any(np.isnan(values[:, 3])) else None
    _check_increasing(alpha, row_lines, src, "Alpha", "Alpha")
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


# ---------------------------------------------------------------- main input file
def read_aerodyn_afnames(path) -> list[str]:
    """The ``AFNames`` list of an AeroDyn v15 main input file.

    Parameters
    ----------
    path : str or Path
        AeroDyn main input file.

    Returns
    -------
    list of str
        ``NumAFfiles`` airfoil file names as written (quotes removed, relative paths
        not resolved). ``BlAFID = k`` in the blade file refers to name ``k - 1``.
    """
    lines, src = _read_lines(path)
    i_n = _find_keyword(lines, "NumAFfiles", 0)
    if i_n is None:
        raise InputError("keyword NumAFfiles not found", src, len(lines), "NumAFfiles")
    n_files = _count(_tokens(lines[i_n])[0], src, i_n + 1, "NumAFfiles")
    i_names = _find_keyword(lines, "AFNames", i_n + 1)
    if i_names is None:
        raise InputError("keyword AFNames not found after NumAFfiles", src, i_n + 1, "AFNames")
    names = []
    i = i_names
    while len(names) < n_files and i < len(lines):
        line = lines[i]
        i += 1
        if _is_comment(line):
            continue
        m = _TOKEN.match(line.strip())
        quoted, bare = m.group(1), m.group(2)
        if quoted is None and (bare.startswith("=") or bare.startswith("-") or "." not in bare):
            break
        names.append(quoted if quoted is not None else bare)
    if len(names) < n_files:
        raise InputError(f"NumAFfiles = {n_files} but only {len(names)} file names follow",
                         src, i_n + 1, "NumAFfiles")
    return names


# ---------------------------------------------------------------- keyword lookup
@dataclass(frozen=True)
class KeyedValue:
    """One ``value  Keyword`` line of an OpenFAST input file.

    Attributes
    ----------
    text : str
        The value as written, quotes removed.
    quoted : bool
        Whether the value was quoted.
    line : int
        1-based line number.
    key : str
        The keyword as spelled in the file.
    """

    text: str
    quoted: bool
    line: int
    key: str


class InputFileValues:
    """The ``value  Keyword  - description`` lines of an OpenFAST input file, by keyword.

    OpenFAST reads its input files line by line in a fixed order that changes between
    versions; looking values up by their keyword instead reads every generation that
    keeps the keyword. Keywords match case-insensitively (``PLExp`` = ``PLexp``); the first
    occurrence wins. Every error names the file, the line and the keyword.

    Parameters
    ----------
    path : str or Path
        The input file.
    """

    def __init__(self, path):
        self.path = Path(path)
        lines, self.source = _read_lines(path)
        self.n_lines = len(lines)
        self._values: dict[str, KeyedValue] = {}
        for i, line in enumerate(lines):
            if _is_comment(line):
                continue
            tokens = list(_TOKEN.finditer(line))
            if len(tokens) < 2 or tokens[1].group(1) is not None:
                continue
            first = tokens[0]
            quoted = first.group(1) is not None
            text = first.group(1) if quoted else first.group(2)
            key = tokens[1].group(2)
            self._values.setdefault(key.lower(), KeyedValue(text, quoted, i + 1, key))

    def __contains__(self, key: str) -> bool:
        return key.lower() in self._values

    def get(self, key: str) -> KeyedValue | None:
        """The value of ``key``, or None when the file does not have it."""
        return self._values.get(key.lower())

    def require(self, key: str, expected: str) -> KeyedValue:
        """The value of ``key``; an :class:`InputError` naming ``expected`` when absent."""
        value = self.get(key)
        if value is None:
            raise InputError(f"keyword {key} not found; expected a line '<{expected}>  {key}'",
                             self.source, None, key)
        return value

    def number(self, key: str, expected: str = "number", allow_default: bool = False) -> float | None:
        """A finite number; ``"default"`` gives None when ``allow_default``."""
        value = self.require(key, expected)
        if allow_default and value.text.strip().lower() == "default":
            return None
        try:
            out = float(value.text)
        except ValueError:
            hint = ' or "default"' if allow_default else ""
            raise InputError(f"expected {expected}{hint}, got {value.text!r}", self.source, value.line,
                             value.key) from None
        if not np.isfinite(out):
            raise InputError(f"expected a finite {expected}, got {value.text!r}", self.source, value.line,
                             value.key)
        return out

    def integer(self, key: str, expected: str = "integer switch") -> int:
        """An integer (switches, counts)."""
        value = self.require(key, expected)
        try:
            return int(value.text)
        except ValueError:
            raise InputError(f"expected an {expected}, got {value.text!r}", self.source, value.line,
                             value.key) from None

    def flag(self, key: str) -> bool:
        """A logical flag (``True``/``False``, ``T``/``F``, any case)."""
        value = self.require(key, "True or False")
        word = value.text.strip().lower()
        if word in ("true", "t"):
            return True
        if word in ("false", "f"):
            return False
        raise InputError(f"expected True or False, got {value.text!r}", self.source, value.line, value.key)

    def file(self, key: str, required: bool = True) -> Path | None:
        """The file named by ``key``, resolved relative to this file's folder.

        ``"unused"`` or an empty name gives None when not ``required``.

        Raises
        ------
        InputError
            The keyword is missing, the name is ``"unused"`` while ``required``, or the
            file does not exist (the error names this file, the line and ``key``).
        """
        value = self.require(key, "quoted file name")
        return resolve_input_file(value.text, self, value.line, value.key, required)


def resolve_input_file(name: str, referrer: InputFileValues, line: int, key: str,
                       required: bool = True) -> Path | None:
    """Resolve a file name written in an OpenFAST input file.

    Relative names are relative to the folder of the referring file (OpenFAST's rule);
    Windows separators are accepted.
    """
    text = name.strip()
    if text == "" or text.lower() in ("unused", "none"):
        if required:
            raise InputError(f"a file is needed here, got {name!r}", referrer.source, line, key)
        return None
    text = text.replace("\\", "/")
    path = Path(text)
    if not path.is_absolute() and not PureWindowsPath(name).is_absolute():
        path = referrer.path.parent / PurePosixPath(text)
    try:
        exists = path.is_file()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise InputError(f"cannot use the file name it gives: {name[:80]!r}{'...' if len(name) > 80 else ''} "
                         f"({exc.strerror or exc})", referrer.source, line, key) from None
    if not exists:
        raise InputError(f"the file it names does not exist: {name!r} (looked for {path})",
                         referrer.source, line, key)
    return path


# ---------------------------------------------------------------- main input: BEM set-up
@dataclass(frozen=True)
class AeroDynMain:
    """What an AeroDyn v15 main input file says about the rotor model and the fluid.

    Attributes
    ----------
    blade_file : Path
        ``ADBlFile(1)``, resolved relative to the main file.
    airfoil_files : tuple of Path
        ``AFNames`` in order (``BlAFID = k`` uses entry k - 1), resolved.
    generation : int
        1: ``WakeMod``/``AFAeroMod`` (OpenFAST <= 3.5); 2: ``Wake_Mod``/``UA_Mod`` (OpenFAST 4).
    wake_model : int
        0 none, 1 BEMT, 2 dynamic BEMT (generation 1 only), 3 OLAF.
    unsteady_airfoil : bool
        Unsteady airfoil aerodynamics on (``AFAeroMod = 2`` or ``UA_Mod > 0``).
    tip_loss, hub_loss : bool
        ``TipLoss``, ``HubLoss``: Prandtl factors.
    tangential_induction : bool
        ``TanInd``.
    drag_in_axial_induction, drag_in_tangential_induction : bool
        ``AIDrag``, ``TIDrag``.
    air_density : float or None
        ``AirDens`` [kg/m^3]; None when the file says ``"default"`` (the OpenFAST glue code
        then supplies the ``.fst`` value, see :func:`calib.rotor.openfast.read_openfast`).
    kinematic_viscosity : float or None
        ``KinVisc`` [m^2/s]; None for ``"default"``.
    source : str
        The file.
    lines : dict
        Keyword -> 1-based line of each value read (for messages).
    """

    blade_file: Path
    airfoil_files: tuple[Path, ...]
    generation: int
    wake_model: int
    unsteady_airfoil: bool
    tip_loss: bool
    hub_loss: bool
    tangential_induction: bool
    drag_in_axial_induction: bool
    drag_in_tangential_induction: bool
    air_density: float | None
    kinematic_viscosity: float | None
    source: str
    lines: dict


def _afnames_with_lines(values: InputFileValues) -> list[tuple[str, int]]:
    """``AFNames`` entries with their 1-based lines (the list runs over NumAFfiles lines)."""
    names = read_aerodyn_afnames(values.path)
    lines, _ = _read_lines(values.path)
    start = values.require("AFNames", "quoted file name").line - 1
    out, i = [], start
    while len(out) < len(names) and i < len(lines):
        if not _is_comment(lines[i]):
            out.append((names[len(out)], i + 1))
        i += 1
    return out


def read_aerodyn_main(path) -> AeroDynMain:
    """Read the BEM set-up and the fluid of an AeroDyn v15 main input file.

    Both field generations are read (``WakeMod``/``AFAeroMod`` and ``Wake_Mod``/``UA_Mod``);
    values are looked up by keyword, so the line order of a generation does not matter.
    ``AirDens`` and ``KinVisc`` may be ``"default"`` (OpenFAST then takes them from the
    ``.fst``): they are returned as None, never replaced by a guess.

    Parameters
    ----------
    path : str or Path
        AeroDyn main input file.

    Returns
    -------
    AeroDynMain

    Raises
    ------
    InputError
        A keyword missing, a value of the wrong kind, both or neither of ``WakeMod`` and
        ``Wake_Mod``, or a referenced blade or airfoil file that does not exist (naming
        this file, the line and the keyword).
    """
    v = InputFileValues(path)
    src = v.source
    if "WakeMod" in v and "Wake_Mod" in v:
        raise InputError("both WakeMod (OpenFAST <= 3.5) and Wake_Mod (OpenFAST 4) are present; "
                         "a file uses one generation", src, v.get("Wake_Mod").line, "Wake_Mod")
    if "Wake_Mod" in v:
        generation = 2
        wake = v.integer("Wake_Mod")
        unsteady = v.integer("UA_Mod") != 0
        lines = {"Wake_Mod": v.get("Wake_Mod").line, "UA_Mod": v.get("UA_Mod").line}
    elif "WakeMod" in v:
        generation = 1
        wake = v.integer("WakeMod")
        af_mod = v.integer("AFAeroMod")
        if af_mod not in (1, 2):
            raise InputError(f"expected 1 (steady) or 2 (Beddoes-Leishman), got {af_mod}", src,
                             v.get("AFAeroMod").line, "AFAeroMod")
        unsteady = af_mod == 2
        lines = {"WakeMod": v.get("WakeMod").line, "AFAeroMod": v.get("AFAeroMod").line}
    else:
        raise InputError("neither WakeMod (OpenFAST <= 3.5) nor Wake_Mod (OpenFAST 4) found: "
                         "not an AeroDyn v15 main input file?", src, None, "WakeMod")
    valid_wake = (0, 1, 2, 3) if generation == 1 else (0, 1, 3)
    if wake not in valid_wake:
        key = "WakeMod" if generation == 1 else "Wake_Mod"
        raise InputError(f"expected one of {valid_wake}, got {wake}", src, v.get(key).line, key)
    flags = {}
    for key in ("TipLoss", "HubLoss", "TanInd", "AIDrag", "TIDrag"):
        flags[key] = v.flag(key)
        lines[key] = v.get(key).line
    fluid = {}
    for key, what in (("AirDens", "density [kg/m^3]"), ("KinVisc", "kinematic viscosity [m^2/s]")):
        fluid[key] = v.number(key, f"a {what}", allow_default=True)
        lines[key] = v.get(key).line
        if fluid[key] is not None and fluid[key] <= 0:
            raise InputError(f"must be > 0, got {fluid[key]:g}", src, lines[key], key)
    blade = v.file("ADBlFile(1)")
    lines["ADBlFile(1)"] = v.get("ADBlFile(1)").line
    airfoils = tuple(resolve_input_file(name, v, line, "AFNames") for name, line in _afnames_with_lines(v))
    lines["AFNames"] = v.get("AFNames").line
    return AeroDynMain(blade_file=blade, airfoil_files=airfoils, generation=generation, wake_model=wake,
                       unsteady_airfoil=unsteady, tip_loss=flags["TipLoss"], hub_loss=flags["HubLoss"],
                       tangential_induction=flags["TanInd"], drag_in_axial_induction=flags["AIDrag"],
                       drag_in_tangential_induction=flags["TIDrag"], air_density=fluid["AirDens"],
                       kinematic_viscosity=fluid["KinVisc"], source=src, lines=lines)


# ---------------------------------------------------------------- rotor
def rotor_from_aerodyn(blade_file, polar_files, hub_radius: float, n_blades: int, precone_deg: float,
                       tilt_deg: float, hub_height: float, name: str,
                       schedule: OperatingSchedule | None = None, source: str | None = None,
                       tip_radius: float | None = None) -> Rotor:
    """Build a :class:`Rotor` from an AeroDyn blade file and its airfoil files.

    Parameters
    ----------
    blade_file : str or Path
        AeroDyn v15 blade file.
    polar_files : sequence of (str, Path or Airfoil)
        Airfoil files (or already-read airfoils) in ``AFNames`` order: BlAFID = k uses
        entry k - 1.
    hub_radius : float
        Hub radius [m]; the blade root lies there, so r = hub_radius + BlSpn.
    n_blades : int
    precone_deg, tilt_deg : float
        [deg], conventions of :class:`Rotor`.
    hub_height : float
        [m].
    name : str
    schedule : OperatingSchedule, optional
    source : str, optional
        Provenance; default the blade file name.
    tip_radius : float, optional
        Tip radius [m]; default hub_radius + last BlSpn. Stations outside
        [hub_radius, tip_radius] are an error.

    Returns
    -------
    Rotor
        precurve = -BlCrvAC (the Rotor's CCBlade convention, positive away from the tower,
        while AeroDyn's BlCrvAC is positive downwind), presweep = BlSwpAC [m]; twist =
        BlTwist [deg]; airfoil ids 0-based.
    """
    blade = read_aerodyn_blade(blade_file)
    src = blade["source"]
    airfoils = tuple(p if isinstance(p, Airfoil) else read_aerodyn_polar(p) for p in polar_files)
    hub = float(hub_radius)
    r = hub + blade["span"]
    tip = float(r[-1]) if tip_radius is None else float(tip_radius)
    tol = 1e-9 * max(abs(tip), 1.0)
    bad = np.flatnonzero((r < hub - tol) | (r > tip + tol))
    if bad.size:
        k = bad[0]
        raise InputError(f"station at r = hub_radius + BlSpn = {r[k]:g} m lies outside [hub, tip] = "
                         f"[{hub:g}, {tip:g}] m", src, int(blade["line"][k]), "BlSpn")
    ids = blade["af_id"]
    bad = np.flatnonzero(ids > len(airfoils))
    if bad.size:
        k = bad[0]
        raise InputError(f"BlAFID = {ids[k]} but only {len(airfoils)} airfoil files were given",
                         src, int(blade["line"][k]), "BlAFID")
    return Rotor(name=name, r=r, chord=blade["chord"], twist_deg=blade["twist"], airfoil_id=ids - 1,
                 airfoils=airfoils, hub_radius=hub, tip_radius=tip, n_blades=n_blades,
                 precone_deg=precone_deg, tilt_deg=tilt_deg, hub_height=hub_height,
                 precurve=-blade["curve_ac"], presweep=blade["sweep_ac"],
                 precurve_tip=-float(blade["curve_ac"][-1]), presweep_tip=float(blade["sweep_ac"][-1]),
                 schedule=schedule, source=source or src)
