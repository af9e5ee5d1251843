"""Reader of the OpenFAST AeroDyn v15 main input file.

- :func:`read_aerodyn_afnames`: the ``AFNames`` list.
- :func:`read_aerodyn_main`: the BEM set-up, fluid and file names, both field generations
  (:class:`AeroDynMain`).

AeroDyn main-file field generations (both read):

1. OpenFAST up to 3.5: ``WakeMod`` {0 none, 1 BEMT, 2 DBEMT, 3 OLAF} and ``AFAeroMod``
   {1 steady, 2 Beddoes-Leishman with ``UAMod``};
2. OpenFAST 4: ``Wake_Mod`` {0 none, 1 BEMT, 3 OLAF} (dynamic BEMT moved to ``DBEMT_Mod``)
   and ``UA_Mod`` {0 quasi-steady, 2..7 unsteady models}.

Reference: OpenFAST documentation, AeroDyn v15 input files
(https://openfast.readthedocs.io, "AeroDyn Input Files").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from calib.errors import InputError
from calib.rotor.input_file import (TOKEN, InputFileValues, read_count, find_keyword, is_comment, read_lines,
                                    tokens_of, resolve_input_file)


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
    lines, src = read_lines(path)
    i_n = find_keyword(lines, "NumAFfiles", 0)
    if i_n is None:
        raise InputError("keyword NumAFfiles not found", src, len(lines), "NumAFfiles")
    n_files = read_count(tokens_of(lines[i_n])[0], src, i_n + 1, "NumAFfiles")
    i_names = find_keyword(lines, "AFNames", i_n + 1)
    if i_names is None:
        raise InputError("keyword AFNames not found after NumAFfiles", src, i_n + 1, "AFNames")
    names = []
    i = i_names
    while len(names) < n_files and i < len(lines):
        line = lines[i]
        i += 1
        if is_comment(line):
            continue
        m = TOKEN.match(line.strip())
        quoted, bare = m.group(1), m.group(2)
        if quoted is None and (bare.startswith("=") or bare.startswith("-") or "." not in bare):
            break
        names.append(quoted if quoted is not None else bare)
    if len(names) < n_files:
        raise InputError(f"NumAFfiles = {n_files} but only {len(names)} file names follow",
                         src, i_n + 1, "NumAFfiles")
    return names


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
    lines, _ = read_lines(values.path)
    start = values.require("AFNames", "quoted file name").line - 1
    out, i = [], start
    while len(out) < len(names) and i < len(lines):
        if not is_comment(lines[i]):
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

