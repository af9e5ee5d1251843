"""Rotor geometry, airfoil polars, readers and the embedded rotors."""

from calib.rotor.geometry import OperatingSchedule, Rotor
from calib.rotor.polar import Airfoil, PolarTable

__all__ = ["Airfoil", "OperatingSchedule", "PolarTable", "Rotor"]
