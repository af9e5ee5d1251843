"""Checks of a calibration's inputs and outputs, each with its findings in words:

- :mod:`calib.checks.unit_check`     unit mistakes in a measurement table, found before a calibration
  (the findings and their words in :mod:`calib.checks.unit_findings`);
- :mod:`calib.checks.prior_check`    a stated prior amplitude against what the data say (type-II ML);
- :mod:`calib.checks.envelope`       whether a predicted point lies where the calibration's data were.
"""
