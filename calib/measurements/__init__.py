"""Measurement tables: the contract's names and units, and the files they are read from.

- :mod:`calib.measurements.data`    :class:`Measurements`, names and units, noise helpers, synthetic data;
- :mod:`calib.measurements.reader`  :func:`read_measurements`: CSV and OpenFAST text output, with the
  checks and notes its docstring lists;
- :mod:`calib.measurements.dataframe` :func:`read_dataframe`: a pandas DataFrame, with the same checks;
- :mod:`calib.measurements.table`   a file split into header, units row and data lines;
- :mod:`calib.measurements.cells`   cells, headers and units: decoding, delimiters, numbers.

Everything public of data, reader and dataframe is importable from here.
"""

from calib.measurements.data import (MISSING_CELLS, REQUIRED_CONDITIONS, UNIT_ALIASES, UNITS,
                                     Measurements, canonical_unit, check_channels, condition_groups, is_channel_name,
                                     ml_noise, noise_from_repeats, normalize_name, quantity_of, sha256_of, si_unit,
                                     synthesize)
from calib.measurements.dataframe import read_dataframe
from calib.measurements.reader import read_measurements
from calib.types import CONDITION_DEFAULTS

__all__ = ["CONDITION_DEFAULTS", "MISSING_CELLS", "REQUIRED_CONDITIONS", "UNITS", "UNIT_ALIASES", "Measurements",
           "canonical_unit", "check_channels", "condition_groups", "is_channel_name", "ml_noise", "noise_from_repeats",
           "normalize_name", "quantity_of", "read_dataframe", "read_measurements", "sha256_of", "si_unit", "synthesize"]
