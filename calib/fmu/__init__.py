"""The rotor FMUs built from ``fmu_models/`` (C sources) and their resources.

- :func:`calib.fmu.build.build_fmu` builds (or fetches from the cache) variant ``"A"``
  (FMI 2.0) or ``"B"`` (FMI 3.0) for a calib rotor and correction grid.
- :func:`calib.fmu.build.mapping_path` gives the variant's declarative mapping file.
- :mod:`calib.fmu.resources` writes the rotor data the FMU reads at instantiation.

The FMU adapter (a ForwardModel) lives elsewhere; this package only builds FMUs.
"""

from calib.fmu.build import FmuBuildError, build_fmu, cache_dir, mapping_path
from calib.fmu.resources import default_grid

__all__ = ["FmuBuildError", "build_fmu", "cache_dir", "default_grid", "mapping_path"]
