"""Builder of the bundled test FMUs: the rotor FMUs compiled from ``fmu_models/`` (C sources).

- :func:`calib.fmu.build.build_fmu` builds (or fetches from the cache) variant ``"A"``
  (FMI 2.0) or ``"B"`` (FMI 3.0) for a calib rotor and correction grid.
- :func:`calib.fmu.build.mapping_path` gives the variant's declarative mapping file.
- :mod:`calib.fmu.resources` writes the rotor data the FMU reads at instantiation.

This package only *builds* FMUs (for tests, benchmarks and demonstrations). The adapter
that drives any vendor's FMU as a ForwardModel lives with the other models:
:class:`calib.models.fmu_model.FmuModel`, with the mapping loader
:mod:`calib.models.fmu_mapping` and the worker processes :mod:`calib.models.fmu_worker`.
"""

from calib.fmu.build import FmuBuildError, build_fmu, cache_dir, mapping_path
from calib.fmu.resources import default_grid

__all__ = ["FmuBuildError", "build_fmu", "cache_dir", "default_grid", "mapping_path"]
