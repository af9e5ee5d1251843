"""The calibration: the problem, its estimators and their uncertainty, and the result.

- :mod:`calib.calibration.calibrator`       :class:`Calibrator` (orchestrates the steps), :func:`calibrate`;
- :mod:`calib.calibration.settings`         :class:`CalibrationSettings`;
- :mod:`calib.calibration.problem`          the least-squares problem and its linearization;
- :mod:`calib.calibration.gauss_newton`     the ML and MAP estimators: damped Gauss–Newton under bounds;
- :mod:`calib.calibration.qp`               the quadratic programs of its steps, by name;
- :mod:`calib.calibration.noise`            the noise σ to start from;
- :mod:`calib.calibration.identifiability`  Fisher information, SVD, verdicts, eigenshapes;
- :mod:`calib.calibration.frozen_curvature` the covariance the frozen directions add through the curvature;
- :mod:`calib.calibration.fold_directions`  retained directions a point near a fold of the BEM equations determines;
- :mod:`calib.calibration.truncation`       the cross-validated choice of the retained count;
- :mod:`calib.calibration.tightening`       which measurements would tighten a parameter's σ;
- :mod:`calib.calibration.uncertainty`      the estimators' covariances from named parts;
- :mod:`calib.calibration.uncertainty_terms` the terms of the problem that need the model;
- :mod:`calib.calibration.map_agreement`    the MAP's self-check against the ML fit;
- :mod:`calib.calibration.result`           :class:`CalibrationResult`, with its parts in
  :mod:`~calib.calibration.result_parts`, built by :mod:`~calib.calibration.result_assembly`,
  written with :mod:`~calib.calibration.result_io` and read back by :mod:`~calib.calibration.result_files`;
- :mod:`calib.calibration.prediction`       predictions with intervals; ``calib predict`` is
  :mod:`~calib.calibration.predict_command`;
- :mod:`calib.calibration.frames`           results and predictions as pandas DataFrames.

The names a script needs are importable from here: ``from calib.calibration import
Calibrator, CalibrationSettings``.
"""

from calib.calibration.calibrator import Calibrator, calibrate
from calib.calibration.prediction import Prediction
from calib.calibration.result import CalibrationResult
from calib.calibration.result_files import load_result
from calib.calibration.settings import ESTIMATORS, NOISE_MODES, CalibrationSettings

__all__ = ["ESTIMATORS", "NOISE_MODES", "CalibrationResult", "CalibrationSettings", "Calibrator", "Prediction",
           "calibrate", "load_result"]
