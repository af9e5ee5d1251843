"""What one fit of the calibrator's estimators returns (:class:`FitOutcome`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.identifiability import SvdAnalysis
from calib.calibration.problem import Linearization


@dataclass
class FitOutcome:
    """One fit of :class:`calib.calibration.truncated_fit.TruncatedFit` or
    :class:`calib.calibration.map_fit.MapFit`.

    Attributes
    ----------
    p : ndarray, shape (n_params,)
        The estimate [parameter units].
    svd : SvdAnalysis
        The truncated estimator's retained set at ``lin``, or the MAP's directions (data against
        prior, :func:`calib.calibration.uncertainty.laplace_covariance`).
    lin : Linearization
        The model at ``p``.
    status : str
        ``converged``, ``not_stable``, ``stalled``, ``max_iterations`` or ``failed``.
    message : str
        The status in words.
    """

    p: np.ndarray
    svd: SvdAnalysis
    lin: Linearization
    status: str
    message: str
