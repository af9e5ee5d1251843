"""The parts of a calibration result: estimate, identifiability, uncertainty, fit, provenance.

:class:`calib.calibration.result.CalibrationResult` holds one of each (pyPESTO-style nested results). Each
part is a plain data class; the calibrator builds it in one step. Shapes: n = n_params,
m = n_points, c = n_channels, r = n_retained.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from calib.calibration.result_io import package_versions


def _empty(*shape):
    return field(default_factory=lambda: np.zeros(shape))


@dataclass(eq=False)
class Estimate:
    """What the estimator found.

    Attributes
    ----------
    p_nominal, p_hat, lower, upper, scale : ndarray, shape (n,)
        Nominal and estimated parameters, effective bounds and scales [parameter units].
    theta_hat : ndarray, shape (r,)
        Retained θ = V_IDᵀ p̃ (truncated) or the directions' coordinates the data determine
        better than the prior (MAP) [scale units].
    status, message : str
        How the estimator ended (``converged``, ``not_stable``, ``max_iterations``, ``stalled``,
        ``failed``) and why.
    history : list of dict
        The progress records of every iteration.
    """

    p_nominal: np.ndarray
    p_hat: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    scale: np.ndarray
    theta_hat: np.ndarray
    status: str
    message: str
    history: list[dict] = field(default_factory=list)


@dataclass(eq=False)
class Identifiability:
    """What the data determine: the directions, their spectrum and the verdicts.

    Attributes
    ----------
    singular_values, V, sigma_theta, retained : ndarray, shapes (n,), (n, n), (n,), (n,) bool
        SVD of the whitened scaled sensitivities at p̂ (docs/theory.md, Estimation).
    sigma_bar : float
        The truncation threshold on σ(θ) [scale units].
    correlation, crb_std : ndarray, shapes (n, n), (n,)
        Cramér–Rao correlation matrix and standard deviations [parameter units] of the full nodal problem.
    observability : ndarray, shape (n,)
        Fraction of each scaled parameter inside the retained subspace [-].
    verdicts : list of dict
        Per parameter: ``identified``, ``poorly observable``, ``at bound`` or ``confounded``, and why.
    confounding : dict
        Per non-field parameter, its information shared with the others
        (:func:`calib.calibration.identifiability.confounding`).
    truncation : dict
        The automatic-truncation curve (:class:`calib.calibration.truncation.TruncationCurve`), empty for an
        explicit σ̄.
    fold_directions : list of dict
        Retained θ that a point with several roots of the BEM equations determines (more than
        half of the θ's information, :func:`calib.calibration.fold_directions.fold_dominated_directions`):
        ``point``, ``theta`` (1-based), ``share``, ``sensitivity_ratio`` and the σ along the
        direction before and after its prior variance was added, ``sigma_before``,
        ``sigma_after`` [scale units]. Empty when there is none.
    tightening : dict
        Which measurements would lower the σ of each parameter that is not a correction node
        (:mod:`calib.calibration.tightening`).
    """

    singular_values: np.ndarray
    V: np.ndarray
    sigma_theta: np.ndarray
    retained: np.ndarray
    sigma_bar: float
    correlation: np.ndarray
    crb_std: np.ndarray
    observability: np.ndarray
    verdicts: list[dict]
    confounding: dict = field(default_factory=dict)
    truncation: dict = field(default_factory=dict)
    fold_directions: list = field(default_factory=list)
    tightening: dict = field(default_factory=dict)


@dataclass(eq=False)
class Uncertainty:
    """How well the estimate is known.

    Attributes
    ----------
    cov_p, std_p : ndarray, shapes (n, n), (n,)
        Covariance / standard deviation of p̂ [parameter units² / parameter units], including the
        prior variance of the directions the data do not determine
        (:func:`calib.calibration.identifiability.frozen_aware_covariance`).
    cov_theta : ndarray, shape (r, r)
        Covariance of the retained θ [scale units²].
    prior_std : ndarray, shape (n,)
        Prior 1-σ of each parameter [parameter unit].
    cov_frozen : ndarray, shape (n, n)
        The frozen directions' part of ``cov_p`` (what the prior, not the data, says).
    fit_scale : float
        Factor on the covariance from the misfit, max(1, χ²/dof) with ``scale_by_fit`` and a
        stated noise (1: not scaled) [-].
    aliasing_chi2 : float
        The χ² after that the field between the nodes is expected to add on average (prior
        average, :mod:`calib.parametrizations.aliasing`; 0 where that term does not apply) [-].
    aliasing_note : str
        Why the bands leave that term out ('' when it is in, or when there is no correction
        field or nothing retained for it to act on).
    curvature : dict
        The frozen directions' prior propagated through the model's curvature to the retained
        θ (:func:`calib.calibration.frozen_curvature.frozen_curvature_covariance`): ``samples`` drawn (0: the
        term is left out), ``used``, ``samples_with_failed_points``, and its variance against
        the noise part per retained θ, ``variance_ratio_mean`` and ``variance_ratio_max`` [-];
        empty when nothing was frozen or nothing retained.
    prior_check : dict
        The data's estimate of the correction field's prior amplitude
        (:class:`calib.checks.prior_check.PriorCheck` as a dict); empty without a correction field or
        with the check off; ``{"failed": message}`` when it could not be computed.
    gain, cov_alias : ndarray, shapes (n, m·c) and (n, n)
        The MAP estimate's linear response to the whitened data [scale units] and the part of
        ``cov_p`` from the field between the nodes [parameter units²]; empty for the truncated
        estimator or without that term.
    polar_bands : dict
        Confidence bands of the corrected polars (:meth:`calib.parametrizations.correction_field.CorrectionField.bands`).
    """

    cov_p: np.ndarray
    std_p: np.ndarray
    cov_theta: np.ndarray
    prior_std: np.ndarray = _empty(0)
    cov_frozen: np.ndarray = _empty(0, 0)
    fit_scale: float = 1.0
    aliasing_chi2: float = 0.0
    aliasing_note: str = ""
    curvature: dict = field(default_factory=dict)
    prior_check: dict = field(default_factory=dict)
    gain: np.ndarray = _empty(0, 0)
    cov_alias: np.ndarray = _empty(0, 0)
    polar_bands: dict = field(default_factory=dict)


@dataclass(eq=False)
class Fit:
    """The model against the measurements, before and after.

    Attributes
    ----------
    measured, sigma, model_before, model_after : ndarray, shape (m, c)
        Measured values, their noise 1-σ, the nominal and the calibrated model [channel units].
    status_before, status_after : ndarray of int, shape (m,)
        Per-point model status (0: converged).
    noise_sigma : ndarray, shape (c,)
        Per-channel noise used in the final estimate [channel units].
    chi2_before, chi2_after : float
        χ² of the whitened residuals at the converged points [-].
    alpha_seen, eta_seen : ndarray, shape (k,)
        (α [deg], η [-]) the converged operating points see at p̂ (empty if the model does not
        report it).
    multiple_roots : ndarray of bool, shape (m,)
        Points where the model reported several roots of its equations (native BEM).
    failures : dict
        Failed model points and the model calls made (``nominal``, ``final``,
        ``total_failed_point_evaluations``, ``model_evaluations``, ``model_jacobians``).
    """

    measured: np.ndarray
    sigma: np.ndarray
    model_before: np.ndarray
    model_after: np.ndarray
    status_before: np.ndarray
    status_after: np.ndarray
    noise_sigma: np.ndarray
    chi2_before: float
    chi2_after: float
    alpha_seen: np.ndarray = _empty(0)
    eta_seen: np.ndarray = _empty(0)
    multiple_roots: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    failures: dict = field(default_factory=dict)


@dataclass(eq=False)
class Provenance:
    """Where the result came from and what rebuilds its model.

    Attributes
    ----------
    settings : dict
        The calibration settings, the model's name and the effective lower bounds.
    model_spec : dict or None
        What :func:`calib.models.registry.build_model` needs to rebuild the model (predictions).
    rotor_radius : float or None
        The rotor radius [m] (tip-speed ratios in reports), None when the model has none.
    inputs : dict
        Input files and their SHA-256 hashes.
    versions : dict
        Python's and the numerical packages' versions.
    wall_time : float
        Duration of the calibration [s].
    checks : dict
        Named statements added after the run (e.g. coverage of a known truth in a synthetic run).
    """

    settings: dict
    model_spec: dict | None = None
    rotor_radius: float | None = None
    inputs: dict = field(default_factory=dict)
    versions: dict = field(default_factory=package_versions)
    wall_time: float = 0.0
    checks: dict = field(default_factory=dict)


PARTS = {"estimate": Estimate, "identifiability": Identifiability, "uncertainty": Uncertainty, "fit": Fit,
         "provenance": Provenance}
"""The parts of a result by attribute name."""

ARRAY_FIELDS = tuple((part, f.name) for part, cls in PARTS.items() for f in fields(cls)
                     if f.type in ("np.ndarray", np.ndarray))
"""The (part, field) pairs stored in ``result.npz`` as ``part.field`` (the others go to ``result.json``)."""
