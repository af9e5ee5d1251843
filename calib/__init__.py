"""calib: calibrate wind-turbine lifting-line (blade element momentum) models from rotor loads.

The package is organised along the physics (docs/theory.md, Architecture):

- :mod:`calib.rotor`        rotor geometry, airfoil polars, file readers, embedded rotors
- :mod:`calib.bem`          native steady BEM with exact sensitivities
- :mod:`calib.corrections`  the additive correction field ΔC_L, ΔC_D(α, η)
- :mod:`calib.models`       the ForwardModel contract and its adapters
"""

__version__ = "0.1.0"
