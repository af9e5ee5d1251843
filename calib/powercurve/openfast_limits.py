"""Operating limits of a variable-speed schedule from an OpenFAST deck: :func:`schedule_from_openfast`.

The ``.fst`` names ElastoDyn (``EDFile``: the gearbox ratio ``GBRatio``) and ServoDyn (``ServoFile``).
ServoDyn's generator-torque mode ``VSContrl`` says where the limits are:

- ``1`` (simple variable-speed control): ``VS_RtGnSp`` (rated generator speed [rpm]) and ``VS_RtTq``
  (rated generator torque [N m]), both on the high-speed shaft. Rated aerodynamic power =
  VS_RtGnSp·π/30·VS_RtTq (no drivetrain loss but ``GenEff`` in ElastoDyn/ServoDyn); maximum rotor
  speed = VS_RtGnSp / GBRatio. The simple controller tracks k·Ω² down to standstill: it states no
  minimum speed, nor a design tip-speed ratio or a fine pitch (those are given as arguments).
- ``5`` (Bladed-style DLL): the DLL's input file ``DLL_InFile`` (relative to the ServoDyn file, as
  OpenFAST resolves it) read as a ROSCO ``DISCON.IN`` (``value ! Name - description`` lines):
  ``VS_RefSpd`` and ``VS_MinOMSpd`` (rated and minimum generator speed [rad/s]), ``VS_RtPwr`` (rated
  electrical power [W]), ``VS_GenEff`` [%], ``VS_TSRopt`` [-] and ``PC_FinePit`` [rad]. Rated
  aerodynamic power = VS_RtPwr / (VS_GenEff/100); rotor speeds = generator speeds / GBRatio.

Generator efficiency: ServoDyn's ``GenEff`` [%] (ROSCO's ``VS_GenEff`` when it reads a DISCON.IN;
a difference between the two is a note). References: OpenFAST ServoDyn and ElastoDyn input-file
documentation (https://openfast.readthedocs.io); ROSCO ``DISCON.IN`` documentation
(https://rosco.readthedocs.io, "ROSCO Input File").
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib.errors import InputError
from calib.powercurve.schedule import VariableSpeed
from calib.rotor.input_file import InputFileValues, resolve_input_file

__all__ = ["OpenFastLimits", "read_discon", "schedule_from_openfast"]

RPM_PER_RAD_S = 30.0 / np.pi


@dataclass(frozen=True)
class OpenFastLimits:
    """The schedule read from a deck and where each value came from.

    Attributes
    ----------
    schedule : VariableSpeed
    sources : dict
        Value name -> "file line N: KEY = text".
    notes : tuple of str
    """

    schedule: VariableSpeed
    sources: dict
    notes: tuple = ()


def read_discon(path) -> dict:
    """The ``value ! Name - description`` lines of a ROSCO ``DISCON.IN``: name -> (text, line).

    Multi-valued lines keep their text; the first occurrence of a name wins.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"controller input file not found: {path}", str(path), field="DLL_InFile")
    out = {}
    for k, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        if "!" not in line:
            continue
        value, _, rest = line.partition("!")
        words = rest.split()
        if not value.strip() or not words:
            continue
        out.setdefault(words[0].lower(), (value.strip(), k, words[0]))
    return out


def _discon_number(values: dict, key: str, src: str, unit: str) -> float:
    if key.lower() not in values:
        raise InputError(f"keyword {key} not found; expected a line '<number [{unit}]>  ! {key} - ...' "
                         "(a ROSCO DISCON.IN)", src, None, key)
    text, line, name = values[key.lower()]
    try:
        x = float(text.split()[0])
    except (ValueError, IndexError):
        raise InputError(f"expected a number [{unit}], got {text!r}", src, line, name) from None
    if not np.isfinite(x):
        raise InputError(f"expected a finite number [{unit}], got {text!r}", src, line, name)
    return x


def _simple_vs(sd, gb, design_tsr, fine_pitch, src, notes):
    """Rated power [W], speed limits [rpm], design λ and fine pitch of ``VSContrl = 1``."""
    rt_sp = sd.number("VS_RtGnSp", "rated generator speed [rpm]")
    rt_tq = sd.number("VS_RtTq", "rated generator torque [N m]")
    for key, x in (("VS_RtGnSp", rt_sp), ("VS_RtTq", rt_tq)):
        if not x > 0:
            raise InputError(f"expected > 0, got {x:g} (VSContrl = 1 uses it)", sd.source, sd.get(key).line, key)
        src[key] = f"{sd.source} line {sd.get(key).line}: {key} = {x:g}"
    if design_tsr is None:
        raise InputError("ServoDyn's simple variable-speed control (VSContrl = 1) states no design tip-speed "
                         "ratio: give one", sd.source, sd.get("VSContrl").line, "VSContrl")
    rated = rt_sp / RPM_PER_RAD_S * rt_tq
    max_rpm = rt_sp / gb
    min_rpm = 1e-3 * max_rpm
    notes.append("VSContrl = 1 states no minimum rotor speed: region 2 tracks the tip-speed ratio down to "
                 f"{min_rpm:.3g} rpm")
    if fine_pitch is None:
        fine_pitch = 0.0
        notes.append("VSContrl = 1 states no fine pitch: 0 deg")
    return rated, min_rpm, max_rpm, design_tsr, fine_pitch


def _rosco(sd, gb, gen_eff, design_tsr, fine_pitch, src, notes):
    """Rated power [W], speed limits [rpm], design λ, fine pitch and generator efficiency of a ROSCO DISCON.IN."""
    dll_in = sd.require("DLL_InFile", "quoted file name")
    path = resolve_input_file(dll_in.text, sd, dll_in.line, dll_in.key, True)
    dv = read_discon(path)
    where = str(path)
    ref = _discon_number(dv, "VS_RefSpd", where, "rad/s")
    min_om = _discon_number(dv, "VS_MinOMSpd", where, "rad/s")
    rt_pwr = _discon_number(dv, "VS_RtPwr", where, "W")
    eff = _discon_number(dv, "VS_GenEff", where, "%") / 100.0
    for key, x in (("VS_RefSpd", ref), ("VS_RtPwr", rt_pwr), ("VS_GenEff", eff)):
        if not x > 0:
            raise InputError(f"expected > 0, got {x:g}", where, dv[key.lower()][1], key)
    for key in ("VS_RefSpd", "VS_MinOMSpd", "VS_RtPwr", "VS_GenEff"):
        src[key] = f"{where} line {dv[key.lower()][1]}: {key} = {dv[key.lower()][0]}"
    if abs(eff - gen_eff) > 1e-9:
        notes.append(f"ROSCO's VS_GenEff {100 * eff:g} % differs from ServoDyn's GenEff {100 * gen_eff:g} %: "
                     "the ROSCO value is used")
    gen_eff = eff
    rated = rt_pwr / eff
    max_rpm, min_rpm = ref / gb * RPM_PER_RAD_S, min_om / gb * RPM_PER_RAD_S
    if design_tsr is None:
        design_tsr = _discon_number(dv, "VS_TSRopt", where, "-")
        src["VS_TSRopt"] = f"{where} line {dv['vs_tsropt'][1]}: VS_TSRopt = {design_tsr:g}"
    if fine_pitch is None:
        fine_pitch = float(np.degrees(_discon_number(dv, "PC_FinePit", where, "rad")))
        src["PC_FinePit"] = f"{where} line {dv['pc_finepit'][1]}: PC_FinePit = {dv['pc_finepit'][0]}"
    if "we_gearboxratio" in dv:
        gb_r = _discon_number(dv, "WE_GearboxRatio", where, "-")
        if abs(gb_r - gb) > 1e-6 * gb:
            notes.append(f"ROSCO's WE_GearboxRatio {gb_r:g} differs from ElastoDyn's GBRatio {gb:g}: "
                         "ElastoDyn's is used")
    return rated, min_rpm, max_rpm, design_tsr, fine_pitch, gen_eff


def schedule_from_openfast(fst, rotor_radius: float, design_tsr: float | None = None,
                           fine_pitch: float | None = None, tsr_rule: str = "optimal") -> OpenFastLimits:
    """A :class:`VariableSpeed` schedule from the controller inputs of an OpenFAST deck.

    Parameters
    ----------
    fst : str or Path
        The ``.fst`` file.
    rotor_radius : float
        [m] (the deck's rotor, e.g. :func:`calib.rotor.openfast.rotor_from_openfast`).
    design_tsr : float, optional
        [-]; required with ``VSContrl = 1`` (ServoDyn states none), else ROSCO's ``VS_TSRopt``.
    fine_pitch : float, optional
        [deg]; default 0 with ``VSContrl = 1`` (said in a note), else ROSCO's ``PC_FinePit``.
    tsr_rule : str
        As :meth:`VariableSpeed.from_rotor`.

    Raises
    ------
    InputError
        A missing file or keyword, a value that is not a number (naming the file, line and keyword),
        a ``VSContrl`` other than 1 or 5, limits that cannot be followed (rated speed or power not
        positive, minimum above maximum).
    """
    fst_v = InputFileValues(fst)
    ed = InputFileValues(fst_v.file("EDFile"))
    sd_path = fst_v.file("ServoFile")
    sd = InputFileValues(sd_path)
    gb = ed.number("GBRatio", "gearbox ratio [-]")
    if not gb > 0:
        raise InputError(f"expected a gearbox ratio > 0, got {gb:g}", ed.source, ed.get("GBRatio").line, "GBRatio")
    mode = sd.integer("VSContrl")
    gen_eff = sd.number("GenEff", "generator efficiency [%]") / 100.0
    src = {"GBRatio": f"{ed.source} line {ed.get('GBRatio').line}: GBRatio = {gb:g}",
           "GenEff": f"{sd.source} line {sd.get('GenEff').line}: GenEff = {100 * gen_eff:g} %"}
    notes = []
    if mode == 1:
        rated, min_rpm, max_rpm, design_tsr, fine_pitch = _simple_vs(sd, gb, design_tsr, fine_pitch, src, notes)
    elif mode == 5:
        rated, min_rpm, max_rpm, design_tsr, fine_pitch, gen_eff = _rosco(sd, gb, gen_eff, design_tsr, fine_pitch,
                                                                          src, notes)
    else:
        raise InputError(f"VSContrl = {mode}: calib reads the limits of VSContrl = 1 (simple variable-speed "
                         "control) or 5 (a DLL with a ROSCO DISCON.IN); give the schedule another way",
                         sd.source, sd.get("VSContrl").line, "VSContrl")
    if not 0 < min_rpm <= max_rpm:
        raise InputError(f"the deck's rotor-speed limits cannot be followed: {min_rpm:g}-{max_rpm:g} rpm "
                         "(need 0 < min <= max)", str(sd_path), None, "VSContrl")
    if not design_tsr > 0:
        raise InputError(f"the design tip-speed ratio must be > 0, got {design_tsr!r}", str(sd_path), None,
                         "design_tsr")
    sched = VariableSpeed(float(rated), float(min_rpm), float(max_rpm), float(design_tsr), float(fine_pitch),
                          float(rotor_radius), tsr_rule, float(gen_eff))
    return OpenFastLimits(sched, src, tuple(notes))
