"""Measurement tables: the contract's names and units, and the files they are read from.

- :mod:`calib.measurements.data`    :class:`Measurements`, channel checks, noise helpers, synthetic data;
- :mod:`calib.measurements.units`   the unit table: column names, their quantities and accepted units;
- :mod:`calib.measurements.reader`  :func:`read_measurements`: CSV and OpenFAST text output, with the
  checks and notes its docstring lists;
- :mod:`calib.measurements.columns` which columns are read and in which unit (header and units row);
- :mod:`calib.measurements.rows`    the data rows as numbers in SI units, with their checks;
- :mod:`calib.measurements.dataframe` :func:`read_dataframe`: a pandas DataFrame, with the same checks;
- :mod:`calib.measurements.table`   a file split into header, units row and data lines;
- :mod:`calib.measurements.cells`   cells, headers and units: decoding, delimiters, numbers, missing values;
- :mod:`calib.measurements.openfast_out` OpenFAST text output: channel names, time series.

The package's face (``__all__``) is importable from here: :class:`Measurements` and its helpers, the
unit table, the two readers and :data:`~calib.measurements.cells.MISSING_CELLS`.
"""

from calib.measurements.cells import MISSING_CELLS
from calib.measurements.data import (Measurements, check_channels, condition_groups, ml_noise, noise_from_repeats,
                                     sha256_of, synthesize)
from calib.measurements.dataframe import read_dataframe
from calib.measurements.reader import read_measurements
from calib.measurements.units import (REQUIRED_CONDITIONS, UNIT_ALIASES, UNITS, canonical_unit, is_channel_name,
                                      normalize_name, quantity_of, si_unit)
from calib.types import CONDITION_DEFAULTS

__all__ = ["CONDITION_DEFAULTS", "MISSING_CELLS", "REQUIRED_CONDITIONS", "UNITS", "UNIT_ALIASES", "Measurements",
           "canonical_unit", "check_channels", "condition_groups", "is_channel_name", "ml_noise", "noise_from_repeats",
           "normalize_name", "quantity_of", "read_dataframe", "read_measurements", "sha256_of", "si_unit", "synthesize"]
