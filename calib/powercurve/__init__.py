"""From calibrated polars to a power curve and an AEP with their uncertainty (issue 41).

:func:`calibrated_power_curve` solves an operating schedule (:mod:`calib.powercurve.schedule`)
for the estimate, the nominal parameters and posterior draws; :mod:`calib.powercurve.aep` turns a
binned curve into an annual energy production; :mod:`calib.powercurve.measurement` holds the
measurement items a user states; ``calib powercurve`` (:mod:`calib.powercurve.command`) writes
tables, figures and a report.
"""

from calib.powercurve.aep import aep, aep_weights, rayleigh_cdf, weibull_cdf
from calib.powercurve.curve import CalibratedPowerCurve, calibrated_power_curve, iec_bins, posterior_draws
from calib.powercurve.linearized import delta_method
from calib.powercurve.measurement import MeasurementItem, parse_measurement
from calib.powercurve.schedule import FixedSpeed, ScheduledCurve, TableSchedule, VariableSpeed, schedule_from_table

__all__ = ["CalibratedPowerCurve", "FixedSpeed", "MeasurementItem", "ScheduledCurve", "TableSchedule", "VariableSpeed",
           "aep", "aep_weights", "calibrated_power_curve", "delta_method", "iec_bins", "parse_measurement",
           "posterior_draws", "rayleigh_cdf", "schedule_from_table", "weibull_cdf"]
