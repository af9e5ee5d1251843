"""Synthetic rotors with analytic polars, for tests that must not depend on data files."""

from __future__ import annotations

import numpy as np

from calib.rotor import Airfoil, PolarTable, Rotor


def analytic_polar(cl_alpha=2 * np.pi, alpha_stall_deg=12.0, cd0=0.008, name="analytic") -> Airfoil:
    """A smooth ±180 deg polar: thin-airfoil lift blended into flat-plate lift past stall.

    C_L = w · C_Lα sin α cos α... blended with 2 sin α cos α (flat plate), C_D = cd0 + 1.9 sin² α.
    """
    alpha = np.linspace(-180.0, 180.0, 721)
    a = np.radians(alpha)
    w = 1.0 / (1.0 + (np.abs(alpha) / alpha_stall_deg) ** 8)
    w = np.where(np.abs(alpha) > 90, 0.0, w)
    cl = w * cl_alpha * np.sin(a) * np.cos(a) + (1 - w) * 2.0 * np.sin(a) * np.cos(a)
    cd = cd0 + 1.9 * np.sin(a) ** 2 * (1 - w) + 0.5 * cd0 * w * np.sin(a) ** 2 * 100
    return Airfoil(name, (PolarTable(alpha, cl, cd, source=name),))


def synthetic_rotor(n_stations=15, tip_radius=40.0, hub_fraction=0.06, n_blades=3, design_tsr=7.0,
                    precone_deg=0.0, tilt_deg=0.0, hub_height=80.0, chord_scale=1.0, twist_offset=0.0,
                    precurve_tip=0.0) -> Rotor:
    """An optimum-like (Betz/Schmitz-shaped) blade on an analytic polar."""
    hub = hub_fraction * tip_radius
    r = np.linspace(hub, tip_radius, n_stations)
    lam_r = design_tsr * r / tip_radius
    phi = (2.0 / 3.0) * np.arctan(1.0 / lam_r)
    chord = chord_scale * 8 * np.pi * r / (n_blades * 2 * np.pi * 1.0) * (1 - np.cos(phi))
    chord = np.maximum(chord, 0.02 * tip_radius)
    twist = np.degrees(phi) - 6.0 + twist_offset
    precurve = precurve_tip * ((r - hub) / (tip_radius - hub)) ** 2
    return Rotor("synthetic", r, chord, twist, np.zeros(n_stations, int), (analytic_polar(),), hub,
                 tip_radius, n_blades, precone_deg=precone_deg, tilt_deg=tilt_deg, hub_height=hub_height,
                 precurve=precurve, presweep=np.zeros(n_stations), precurve_tip=precurve_tip)
