"""Native steady BEM: vectorized solve, loads and exact sensitivities."""

from calib.bem.polar_grid import SectionPolars, tabulate_polars
from calib.bem.solver import BemResult, BemSettings, solve_bem

__all__ = ["BemResult", "BemSettings", "SectionPolars", "solve_bem", "tabulate_polars"]
