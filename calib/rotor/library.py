"""Embedded rotors, loadable by name, and the reference tables shipped with the package.

>>> from calib.rotor.library import load_rotor
>>> rotor = load_rotor("nrel5mw")

Names (:data:`ROTORS`): ``nrel5mw``, ``iea3.4``, ``iea15``, ``phase_vi``. Data live in
``calib/data/<folder>/`` with a ``PROVENANCE.txt`` each; independent reference tables
(for validation only) in ``calib/data/reference/`` (:func:`reference_path`).

Phase VI conventions (:func:`load_phase_vi`):

- twist is stored *relative to the tip*: twist_deg = report twist - report tip twist
  (-1.815 deg), positive toward feather, so the tip twist is 0 and a blade pitch of
  :data:`PHASE_VI_TIP_PITCH_DEG` = 3 deg is the test condition of sequences H and S
  (OpenFAST uses BlPitch = 4.815 deg with the report twist: the same section angles).
- stations whose pitch axis sits at 0.50 chord (``chord_mount`` > 0.30 in Table A-1:
  the root cylinder r <= 0.8835 m and the cylinder-to-S809 transition 1.0085-1.1335 m)
  get a cylinder polar (C_L = 0, C_D = :data:`PHASE_VI_ROOT_CD`, subcritical circular
  cylinder at Re ~ 2e5, Hoerner 1965); the S809 polar is used from r = 1.2575 m
  (``chord_mount`` = 0.30) outward.
- S809 drag: the OSU table has pressure drag ``cdp`` at every angle and wake-rake total
  drag ``cdw`` at some. BEM needs total drag, so ``cdw`` is used where measured in
  attached flow (|alpha| <= :data:`S809_ATTACHED_LIMIT_DEG`), ``cdp`` elsewhere (in
  separated flow, pressure drag dominates and the rake is not reported). The
  ``drag="pressure"`` option reproduces the AeroDyn CertTest polar S809_AD15.dat.
"""

from __future__ import annotations

import csv
from pathlib import Path, PurePosixPath

import numpy as np

from calib.errors import InputError
from calib.rotor.aerodyn import rotor_from_aerodyn
from calib.rotor.aerodyn_main import read_aerodyn_afnames
from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import Airfoil, PolarTable
from calib.rotor.viterna import extrapolate_viterna
from calib.rotor.windio import load_windio, windio_rotor_setup, windio_schedule

DATA_DIR = Path(__file__).resolve().parents[1] / "data"

# NREL 5-MW: Jonkman et al., NREL/TP-500-38060 (2009), Table 1-1 and ch. 7.
NREL5MW_GENERATOR_EFFICIENCY = 0.944
NREL5MW_SCHEDULE = OperatingSchedule(
    rated_power=5.0e6 / NREL5MW_GENERATOR_EFFICIENCY, min_rotor_speed=6.9, max_rotor_speed=12.1,
    design_tsr=7.55, fine_pitch=0.0, cut_in=3.0, cut_out=25.0,
    generator_efficiency=NREL5MW_GENERATOR_EFFICIENCY)

# Phase VI: NREL/TP-500-29955 (Hand et al. 2001).
PHASE_VI_TIP_PITCH_DEG = 3.0
PHASE_VI_HUB_HEIGHT = 12.192   # [m], rotor centre above the tunnel floor (TP-500-29955)
PHASE_VI_ROOT_CD = 1.0         # [-], circular cylinder, subcritical Re (Hoerner 1965)
PHASE_VI_ASPECT_RATIO = 11.0   # [-], as the OpenFAST r-test S809 polars (NREL/TP-442-7817)
S809_ATTACHED_LIMIT_DEG = 9.0  # [deg], use wake-rake drag inside |alpha| <= this


# ---------------------------------------------------------------- paths
def data_path(*parts: str) -> Path:
    """Path of a file shipped in ``calib/data`` (error if it does not exist)."""
    path = DATA_DIR.joinpath(*parts)
    if not path.exists():
        raise InputError("package data file not found (broken installation?)", path)
    return path


def reference_path(name: str) -> Path:
    """Path of an independent reference table in ``calib/data/reference``.

    Parameters
    ----------
    name : str
        File name, e.g. ``"IEA-3.4-130-RWT_performance_ccblade.dat"``.
    """
    folder = DATA_DIR / "reference"
    path = folder / name
    if not path.is_file():
        known = sorted(p.name for p in folder.iterdir() if p.name != "PROVENANCE.txt")
        raise InputError(f"unknown reference table; valid names: {', '.join(known)}", name, field="name")
    return path


def _airfoil_files(folder: Path, afnames) -> list[Path]:
    """AFNames entries resolved by file name in ``folder/Airfoils``."""
    return [folder / "Airfoils" / PurePosixPath(n.replace("\\", "/")).name for n in afnames]


# ---------------------------------------------------------------- AeroDyn-based rotors
def load_nrel5mw() -> Rotor:
    """NREL 5-MW reference rotor (AeroDyn 15 blade file, 8 polars via AFNames).

    Hub radius 1.5 m, 3 blades, precone 2.5 deg, shaft tilt 5 deg, hub height 90 m,
    schedule :data:`NREL5MW_SCHEDULE` (Jonkman et al. 2009, NREL/TP-500-38060).
    """
    folder = data_path("nrel5mw")
    polars = _airfoil_files(folder, read_aerodyn_afnames(folder / "NREL5MW_AD15_main_input.dat"))
    return rotor_from_aerodyn(folder / "NRELOffshrBsline5MW_AeroDyn_blade.dat", polars, hub_radius=1.5,
                              n_blades=3, precone_deg=2.5, tilt_deg=5.0, hub_height=90.0, name="nrel5mw",
                              schedule=NREL5MW_SCHEDULE,
                              source="NREL 5-MW, AeroDyn15 files (calib/data/nrel5mw, NREL/TP-500-38060)")


def iea3p4_generator_efficiency() -> float:
    """Electrical / aerodynamic power of the IEA 3.4-MW CCBlade table [-] (mean over rows)."""
    table = np.loadtxt(reference_path("IEA-3.4-130-RWT_performance_ccblade.dat"), comments="#")
    elec, aero = table[:, 3], table[:, 4]
    ok = aero > 0
    return float(np.mean(elec[ok] / aero[ok]))


def load_iea3p4() -> Rotor:
    """IEA Wind 3.4-MW reference rotor (AeroDyn 15 blade file, 30 polars).

    Hub radius, precone, tilt, hub height, blade count and schedule come from the windIO
    file; the generator efficiency from the CCBlade performance table (elec / aero
    power). Tip radius = hub radius + last BlSpn = 64.91 m (windIO: 65.0 m).
    Bortolotti et al., NREL/TP-5000-73492 (2019).
    """
    folder = data_path("iea3p4")
    yaml_file = folder / "IEA-3.4-130-RWT_windIO.yaml"
    data = load_windio(yaml_file)
    schedule = windio_schedule(data, str(yaml_file), iea3p4_generator_efficiency())
    polars = _airfoil_files(folder, read_aerodyn_afnames(folder / "IEA-3.4-130-RWT_AeroDyn15.dat"))
    return rotor_from_aerodyn(folder / "IEA-3.4-130-RWT_AeroDyn15_blade.dat", polars, name="iea3.4",
                              schedule=schedule, **windio_rotor_setup(data, str(yaml_file)),
                              source="IEA 3.4-MW RWT, AeroDyn15 files + windIO (calib/data/iea3p4)")


def iea15_generator_efficiency() -> float:
    """Rated generator efficiency of the IEA 15-MW turbine [-] (tabular documentation)."""
    path = data_path("iea15", "IEA-15-240-RWT_Overview_from_tabular_xlsx.csv")
    with open(path, newline="", encoding="utf-8") as fh:
        for line, row in enumerate(csv.reader(fh), start=1):
            if row and row[0].startswith("Generator rated efficiency"):
                value = float(row[1])
                return value / 100.0 if value > 1.0 else value  # labelled [%] but stored as a fraction
    raise InputError("row 'Generator rated efficiency' not found", path, field="Parameter")


def load_iea15() -> Rotor:
    """IEA Wind 15-MW reference rotor (AeroDyn 15 blade file, 50 polars).

    Hub, orientation and schedule from the windIO file; generator efficiency from the
    tabular documentation. Gaertner et al., NREL/TP-5000-75698 (2020).
    """
    folder = data_path("iea15")
    yaml_file = folder / "IEA-15-240-RWT_windIO.yaml"
    data = load_windio(yaml_file)
    schedule = windio_schedule(data, str(yaml_file), iea15_generator_efficiency())
    polars = _airfoil_files(folder, read_aerodyn_afnames(folder / "IEA-15-240-RWT-Monopile_AeroDyn15_main_input.dat"))
    return rotor_from_aerodyn(folder / "IEA-15-240-RWT_AeroDyn15_blade.dat", polars, name="iea15",
                              schedule=schedule, **windio_rotor_setup(data, str(yaml_file)),
                              source="IEA 15-MW RWT, AeroDyn15 files + windIO (calib/data/iea15)")


# ---------------------------------------------------------------- Phase VI
def _read_csv(path: Path) -> tuple[list[str], list[tuple[int, dict]]]:
    """Rows of a CSV file with '#' comment lines, as (line number, {column: text}).

    The header is the first non-comment line, or the last comment line before the data
    when the first non-comment line is numeric (``# radius_m,chord_m,...``).
    """
    rows, header, last_comment = [], None, None
    with open(path, newline="", encoding="utf-8") as fh:
        for line, cells in enumerate(csv.reader(fh), start=1):
            if not cells:
                continue
            cells = [c.strip() for c in cells]
            if cells[0].startswith("#"):
                last_comment = [cells[0].lstrip("#").strip()] + cells[1:]
                continue
            if header is None:
                numeric = cells[0].replace(".", "", 1).lstrip("-").isdigit()
                if not (numeric and last_comment and len(last_comment) == len(cells)):
                    header = cells
                    continue
                header = last_comment
            if len(cells) != len(header):
                raise InputError(f"expected {len(header)} cells, found {len(cells)}", path, line)
            rows.append((line, dict(zip(header, cells))))
    if header is None:
        raise InputError("no header line", path)
    return header, rows


def _column(path, rows, name, blank_ok=False) -> np.ndarray:
    out = np.empty(len(rows))
    for k, (line, row) in enumerate(rows):
        if name not in row:
            raise InputError("column missing", path, line, name)
        text = row[name]
        if text == "" and blank_ok:
            out[k] = np.nan
            continue
        try:
            out[k] = float(text)
        except ValueError:
            raise InputError(f"expected a number, got {text!r}", path, line, name) from None
        if not np.isfinite(out[k]):
            raise InputError(f"expected a finite number, got {text!r}", path, line, name)
    return out


def phase_vi_s809_table(drag: str = "combined") -> PolarTable:
    """Measured S809 polar, OSU, Re = 1e6 (TP-500-29955 Table A-7), -20.1..26.1 deg.

    Parameters
    ----------
    drag : {"combined", "pressure"}
        ``"combined"``: wake-rake drag ``cdw`` where measured with |alpha| <=
        :data:`S809_ATTACHED_LIMIT_DEG`, pressure drag ``cdp`` elsewhere (default);
        ``"pressure"``: ``cdp`` everywhere (as OpenFAST CertTest S809_AD15.dat).

    Returns
    -------
    PolarTable
        alpha [deg], C_L, C_D, C_M [-], Re = 1e6.
    """
    path = data_path("phase_vi", "table_A7_OSU_Re1.0M.csv")
    _, rows = _read_csv(path)
    alpha = _column(path, rows, "alpha_deg")
    cdp = _column(path, rows, "cdp")
    cdw = _column(path, rows, "cdw", blank_ok=True)
    if drag == "pressure":
        cd = cdp
    elif drag == "combined":
        use_wake = np.isfinite(cdw) & (np.abs(alpha) <= S809_ATTACHED_LIMIT_DEG)
        cd = np.where(use_wake, cdw, cdp)
    else:
        raise InputError(f"unknown drag option {drag!r}; valid: 'combined', 'pressure'", field="drag")
    return PolarTable(alpha, _column(path, rows, "cl"), cd, _column(path, rows, "cm"), 1.0e6,
                      source=str(path), first_line=rows[0][0])


def phase_vi_airfoils(drag: str = "combined") -> tuple[Airfoil, Airfoil]:
    """(cylinder, S809) airfoils of the Phase VI rotor, both covering -180..180 deg.

    The S809 table (:func:`phase_vi_s809_table`) is extended with
    :func:`~calib.rotor.viterna.extrapolate_viterna`, aspect ratio
    :data:`PHASE_VI_ASPECT_RATIO` (C_D,max = 1.308).
    """
    s809 = extrapolate_viterna(phase_vi_s809_table(drag), aspect_ratio=PHASE_VI_ASPECT_RATIO)
    cylinder = PolarTable([-180.0, 0.0, 180.0], [0.0, 0.0, 0.0], [PHASE_VI_ROOT_CD] * 3, [0.0, 0.0, 0.0],
                          source="Phase VI root cylinder (calib.rotor.library.PHASE_VI_ROOT_CD)")
    return (Airfoil("cylinder", (cylinder,), 1.0, notes="root cylinder and transition"),
            Airfoil("S809", (s809,), 0.21, notes="OSU Re 1e6 (TP-500-29955 Table A-7), Viterna-extended"))


def _phase_vi_key_parameters() -> dict:
    path = data_path("phase_vi", "UAE_ElastoDyn_key_parameters.csv")
    _, rows = _read_csv(path)
    return {row["parameter"]: (line, row["value"]) for line, row in rows}


def load_phase_vi(drag: str = "combined") -> Rotor:
    """NREL UAE Phase VI rotor (2 blades, R = 5.029 m, S809).

    Geometry from TP-500-29955 Table A-1 (26 stations r = 0.508..5.029 m), hub radius,
    blade count, tip radius, precone and tilt from the OpenFAST r-test model of the
    same rotor. Twist relative to the tip (see module notes): run at pitch
    :data:`PHASE_VI_TIP_PITCH_DEG` for the test condition. Fixed speed (~72 rpm), so no
    schedule.
    """
    path = data_path("phase_vi", "phaseVI_blade.csv")
    _, rows = _read_csv(path)
    r = _column(path, rows, "radius_m")
    chord = _column(path, rows, "chord_m")
    twist_report = _column(path, rows, "twist_deg_report")
    mount = _column(path, rows, "chord_mount")
    keys = _phase_vi_key_parameters()
    kp_path = data_path("phase_vi", "UAE_ElastoDyn_key_parameters.csv")

    def key(name):
        if name not in keys:
            raise InputError("parameter missing", kp_path, field=name)
        line, text = keys[name]
        try:
            return float(text)
        except ValueError:
            raise InputError(f"expected a number, got {text!r}", kp_path, line, name) from None

    tip = key("TipRad")
    if abs(r[-1] - tip) > 1e-6:
        raise InputError(f"last station {r[-1]:g} m differs from TipRad {tip:g} m", path, rows[-1][0], "radius_m")
    airfoil_id = np.where(mount > 0.3 + 1e-9, 0, 1)
    return Rotor(name="phase_vi", r=r, chord=chord, twist_deg=twist_report - twist_report[-1],
                 airfoil_id=airfoil_id, airfoils=phase_vi_airfoils(drag), hub_radius=key("HubRad"),
                 tip_radius=tip, n_blades=int(key("NumBl")), precone_deg=key("PreCone"),
                 tilt_deg=key("ShftTilt"), hub_height=PHASE_VI_HUB_HEIGHT, schedule=None,
                 source="NREL UAE Phase VI, TP-500-29955 Table A-1 + OSU S809 Re 1e6 (calib/data/phase_vi)")


def load_phase_vi_measurements() -> dict:
    """Measured sequence H means of the Phase VI test (upwind, 0 yaw, 3 deg tip pitch).

    Returns
    -------
    dict
        ``"performance"``: dict of arrays, shape (n_records,) = (6,): ``record`` (file
        name), ``wind_speed`` [m/s], ``yaw`` [deg], ``rotor_speed`` [rpm], ``power``
        [W] (rotor power, from kW), ``lss_torque`` [N m] (corrected low-speed-shaft
        torque), ``thrust`` [N] (aerodynamic thrust), ``air_density`` [kg/m^3].
        ``"spanwise"``: dict with ``r_over_R`` (5,) [-], ``wind_speed`` (6,) [m/s],
        ``record`` (6,), and ``cn``, ``ct``, ``cm`` of shape (6, 5) [-]: pressure-tap
        normal, tangential and pitching-moment coefficients per record and station.

    Source: NREL WDH UAE Phase VI statistics, sheet ldsmean (DOI 10.21947/WDH-DAP/1910052).
    """
    path = data_path("phase_vi", "sequence_H_performance.csv")
    _, rows = _read_csv(path)
    perf = {"record": np.array([row["file_name"] for _, row in rows]),
            "wind_speed": _column(path, rows, "wind_speed_m_s"),
            "yaw": _column(path, rows, "yaw_deg"),
            "rotor_speed": _column(path, rows, "rpm"),
            "power": 1e3 * _column(path, rows, "rotpow_kw"),
            "lss_torque": _column(path, rows, "lsstqcor_nm"),
            "thrust": _column(path, rows, "eaeroth_n"),
            "air_density": _column(path, rows, "rho_kg_m3")}
    path = data_path("phase_vi", "sequence_H_spanwise.csv")
    _, rows = _read_csv(path)
    names = [row["file_name"] for _, row in rows]
    eta = _column(path, rows, "r_over_R")
    stations = np.unique(eta)
    cols = {c: _column(path, rows, c) for c in ("cn", "ct", "cm")}
    span = {"r_over_R": stations, "record": perf["record"], "wind_speed": perf["wind_speed"]}
    for c in cols:
        span[c] = np.full((len(perf["record"]), stations.size), np.nan)
    for k, (line, _) in enumerate(rows):
        if names[k] not in perf["record"]:
            raise InputError(f"record {names[k]!r} is not in sequence_H_performance.csv", path, line, "file_name")
        i = int(np.flatnonzero(perf["record"] == names[k])[0])
        j = int(np.searchsorted(stations, eta[k]))
        for c in cols:
            span[c][i, j] = cols[c][k]
    for c in cols:
        if np.isnan(span[c]).any():
            i, j = np.argwhere(np.isnan(span[c]))[0]
            raise InputError(f"no value for record {perf['record'][i]} at r/R = {stations[j]:g}", path, field=c)
    return {"performance": perf, "spanwise": span}


# ---------------------------------------------------------------- registry
ROTORS = {
    "nrel5mw": load_nrel5mw,
    "iea3.4": load_iea3p4,
    "iea15": load_iea15,
    "phase_vi": load_phase_vi,
}


def load_rotor(name: str = "nrel5mw") -> Rotor:
    """An embedded rotor by name.

    Parameters
    ----------
    name : str
        One of :data:`ROTORS` (case-insensitive): ``nrel5mw``, ``iea3.4``, ``iea15``,
        ``phase_vi``.

    Raises
    ------
    InputError
        Unknown name; the message lists the valid names.
    """
    key = str(name).strip().lower()
    if key not in ROTORS:
        raise InputError(f"unknown rotor {name!r}; valid names: {', '.join(ROTORS)}", field="name")
    return ROTORS[key]()
