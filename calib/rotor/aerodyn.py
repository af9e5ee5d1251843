"""Readers for OpenFAST AeroDyn v15 input files, and a rotor from them.

Each file kind has its own module:

- :func:`~calib.rotor.aerodyn_blade.read_aerodyn_blade`: blade definition file
  (:mod:`calib.rotor.aerodyn_blade`);
- :func:`~calib.rotor.aerodyn_polar.read_aerodyn_polar`: airfoil file
  (:mod:`calib.rotor.aerodyn_polar`);
- :func:`~calib.rotor.aerodyn_main.read_aerodyn_afnames`,
  :func:`~calib.rotor.aerodyn_main.read_aerodyn_main`: main input file, both field
  generations (:mod:`calib.rotor.aerodyn_main`);
- :class:`~calib.rotor.input_file.InputFileValues`: the ``value  Keyword  - description``
  lines of any OpenFAST input file, looked up by keyword (:mod:`calib.rotor.input_file`,
  also used by :mod:`calib.rotor.openfast`).

Here: :func:`rotor_from_aerodyn`, a :class:`~calib.rotor.geometry.Rotor` from these files.

Every error is an :class:`~calib.errors.InputError` naming the file, the 1-based line
and the field (column or keyword as spelled in the file).

Reference: OpenFAST documentation, AeroDyn v15 input files
(https://openfast.readthedocs.io, "AeroDyn Input Files").
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.rotor.aerodyn_blade import read_aerodyn_blade
from calib.rotor.aerodyn_polar import read_aerodyn_polar
from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import Airfoil


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
