"""SCADA 10-minute statistics in: reading, air density, filters, the method of bins, measurement tables.

- :mod:`calib.scada.mapping`  the signals, their units and the column names of common exports;
- :mod:`calib.scada.reader`   :func:`read_scada`: an export read into :class:`ScadaRecords`, gaps and
  duplicate stamps counted;
- :mod:`calib.scada.density`  air density and wind-speed normalization (IEC 61400-12-1);
- :mod:`calib.scada.filters`  :func:`apply_filters`: out of range, frozen, start/stop, curtailment, icing;
- :mod:`calib.scada.bins`     :func:`method_of_bins` (IEC 61400-12-1);
- :mod:`calib.scada.analysis` :func:`power_curve`: the steps above in one call;
- :mod:`calib.scada.table`    bins or records written as a calib measurement table.
"""

from calib.scada.analysis import PowerCurveAnalysis, power_curve, record_density
from calib.scada.bins import PowerCurveBins, bin_index, method_of_bins
from calib.scada.density import (RHO_REFERENCE, air_density, air_density_sigma, normalized_wind_speed,
                                 vapour_pressure)
from calib.scada.filters import FILTERS, FilterReport, FilterSettings, apply_filters, frozen_runs
from calib.scada.mapping import COLUMN_MAP, SIGNALS, column_map
from calib.scada.reader import REQUIRED_SIGNALS, ScadaRecords, read_scada
from calib.scada.table import write_bins_table, write_records_table

__all__ = ["COLUMN_MAP", "air_density_sigma", "FILTERS", "REQUIRED_SIGNALS", "RHO_REFERENCE", "SIGNALS", "FilterReport", "FilterSettings",
           "PowerCurveAnalysis", "PowerCurveBins", "ScadaRecords", "air_density", "apply_filters", "bin_index",
           "column_map", "frozen_runs", "method_of_bins", "normalized_wind_speed", "power_curve", "read_scada",
           "record_density", "vapour_pressure", "write_bins_table", "write_records_table"]
