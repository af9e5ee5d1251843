"""Native steady BEM: vectorized solve through a chain of effects, loads and exact sensitivities."""

from calib.bem.chain import EffectChain
from calib.bem.polar_grid import SectionPolars, tabulate_polars
from calib.bem.solver import BemResult, BemSettings, solve_bem

__all__ = ["BemResult", "BemSettings", "EffectChain", "SectionPolars", "solve_bem", "tabulate_polars"]
