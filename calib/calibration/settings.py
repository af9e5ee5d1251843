"""The settings of a calibration (:class:`CalibrationSettings`): one dataclass, the Python API's and the
workflow's ``[calibration]`` table's (:func:`calib.config.schema_of`), checked by its ``validate``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.qp import get_optimizer
from calib.errors import InputError

NOISE_MODES = ("known", "ml", "repeats", "relative", "relative_ml")
RETAIN_MODES = ("threshold", "all")
ESTIMATORS = ("map", "truncated")
ERRORS_IN_VARIABLES = ("marginal", "joint", "ignore")
JACOBIAN_UPDATES = ("auto", "broyden", "model")
UNCERTAIN_CONDITIONS = ("wind_speed", "rotor_speed", "pitch", "air_density")


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of a calibration.

    Parameters
    ----------
    estimator : {"map", "truncated"}
        ``"map"``: the maximum a posteriori estimate under the stated prior (``prior_sigma``,
        ``prior_std``, ``prior_correlation``) and its Laplace covariance; every parameter moves,
        held by the prior where the data say little, and the SVD of the prior-whitened
        sensitivities gives the directions where the data beat the prior (s_i > 1), their
        eigenshapes and verdicts (:meth:`calib.calibration.map_fit.MapFit.fit`). ``"truncated"``: the truncated
        ML estimate of Bottasso et al. (2014), re-linearized until the retained set is stable,
        with the frozen directions' prior and the added terms below (``sigma_bar``, ``cv_*``,
        ``second_start``, ``curvature_samples``, ``representation_error``'s aliasing term).
    sigma_bar : float or "auto"
        ``"auto"`` (default): retain the number of θ chosen by the K-fold cross-validated
        prediction error over operating points (:func:`calib.calibration.truncation.cv_curve`), among the
        leading directions the data determine better than the prior
        (:func:`calib.calibration.truncation.prior_limit`). A number: retain θ_i with
        σ(θ_i) = 1/s_i <= σ̄, in units of the parameter scales [-]
        (see :func:`calib.calibration.identifiability.sigma_bar_for`).
    cv_folds : int
        K of the K-fold cross-validation over operating points that ``sigma_bar = "auto"`` uses.
    cv_one_se : bool
        Keep the fewest θ within one standard error of the minimum criterion (default) rather
        than the minimum: measured on the wind-tunnel twin, the minimum retains about 40 % more
        θ and their NEES is 1.7× its dimension (overconfident); with the rule it is 0.99×.
    prior_sigma : float
        Prior 1-σ of every parameter without its own ``prior_std``, in units of its scale [-]
        (default 1: a correction node is believed to be within about ±1 scale of nominal,
        ±0.1 on C_L and ±0.01 on C_D with the default scales). It sets the width of the bands
        in the directions the truncation froze.
    prior_std : dict parameter -> float, optional
        Prior 1-σ of named parameters in their own units (e.g. ``{pitch_offset = 0.3}`` [deg]),
        replacing the parameter's default (``Parameter.prior_std``) or ``prior_sigma`` × scale.
        A nuisance with a stated prior cannot absorb what the data do not show: under the MAP
        estimator it moves only as far as the data outweigh that prior, and its variance enters
        every prediction through the covariance.
    prior_correlation : float
        Correlation length of the smooth-field prior on the correction nodes, in node spacings
        [-] (:meth:`calib.parametrizations.CorrectionField.node_correlation`): neighbouring
        nodes of a block are correlated as samples of a field the chosen grid resolves
        (ρ = exp(−½) = 0.61 at one spacing). It sets the prior covariance of the frozen
        directions and the representation variance between the nodes (there with physical
        lengths, no shorter than ``prior_correlation`` × (6°, 0.2):
        :func:`calib.parametrizations.field_prior.between_node_lengths`); 0 gives independent
        nodes and the roughest field between them. On the wind-tunnel twins (10 noise seeds
        each, truth inside and outside the span) the marginal likelihood of the data, with
        the prior scale at its type-II ML value, was highest at 1 among 0, 1, 1.5, 2 and 3.
    retain : {"threshold", "all"}
        ``"all"`` gives the full nodal ML estimate (every direction with s_i > 0).
    max_retained : int, optional
        Cap on the number of retained parameters.
    optimizer : str
        ``sqpmethod``, ``ipopt``, ``slsqp`` or ``trust-constr``.
    noise : {"known", "ml", "repeats", "relative", "relative_ml"}
        Where R comes from: the table's ``_sigma`` columns or ``sigma`` (known), the residuals
        (ml, per channel), repeated records (repeats), a stated fraction of each channel's
        RMS (relative, :mod:`calib.calibration.noise`), or that with one common factor estimated by
        maximum likelihood from the calibrated fit's residuals with N − k degrees of
        freedom (relative_ml: the stated fractions fix the channels' relative weights, the
        data their overall level). With ``ml``, ``relative_sigma`` (if given) is the start
        of the iteration instead of the nominal residual.
    relative_sigma : dict channel-or-group -> float, optional
        The fractions of ``noise = "relative"`` [-], e.g. ``{"torque": 0.03, "cn": 0.05}``
        (``cn`` covers every ``cn@<r/R>`` channel).
    sigma : dict channel -> float, optional
        Absolute 1-σ noise per channel [channel unit]; overrides the table's σ.
    cd_min : float or None
        Lower bound on C_D at the correction nodes [-] (needs ``model.nominal_coefficients``).
    max_relinearizations, max_iterations, max_noise_iterations : int
        Most re-linearizations of the truncated estimator's retained set, Gauss–Newton iterations
        of one estimate, and iterations between the noise estimate and the fit (``ml`` and
        ``relative_ml`` noise).
    tolerance : float
        Relative cost decrease that ends a Gauss–Newton iteration.
    stability_cosine : float
        Principal-angle cosine above which two retained subspaces count as equal.
    representation_error : bool
        Add to the polar bands the variance of the true field between the nodes that the
        hat functions cannot carry
        (:meth:`calib.parametrizations.CorrectionField.representation_variance`).
    scale_by_fit : bool
        When χ² after exceeds its degrees of freedom (with noise ``known``, ``relative`` or
        ``repeats``), multiply the covariance of the retained θ (noise and aliasing) by
        χ²/(N − n_retained): the misfit left is evidence that the stated noise undercounts what
        the data carry (the Birge ratio; Particle Data Group's scale factor). The frozen
        directions' prior part is not scaled. With the ML noise models χ²/dof is 1 by
        construction. Default true (measured in ``benchmarks/bench_coverage.py``, docs/user_guide/calibration.md).
    curvature_samples : int
        Prior draws of the frozen directions propagated through the model to the retained θ
        (:func:`calib.calibration.frozen_curvature.frozen_curvature_covariance`): where the model is not
        linear over the prior's range, the frozen part of the truth biases the retained θ, and
        this adds that bias's second moment to their covariance (not scaled by the fit). Costs
        that many model evaluations per calibration; 0 leaves the term out (the report says so).
    second_start : bool
        With ``sigma_bar = "auto"`` and a stated noise (``known``, ``relative``, ``repeats``):
        when the fit's χ² rejects the stated noise at the 1 % level, run the re-linearization
        loop again from a first estimate with every direction the data determine better than the
        prior (:func:`calib.calibration.truncation.prior_limit`) and keep the result whose cross-validated
        criterion, each at its own final linearization, is lower by more than its standard error
        (the fewer θ otherwise). The choice made from the nominal linearization can settle on few
        θ because that linearization understates what a re-linearized fit with more θ achieves
        (docs/user_guide/calibration.md). Costs a second loop only for such fits; the report says which start was kept.
    prior_check : bool
        Estimate the correction field's prior amplitude from the data and say whether the stated
        prior is consistent with it (:mod:`calib.checks.prior_check`; about six model Jacobians to the MAP
        under the stated prior, and one on the fine grid). False skips it (the report says so);
        the refits of a leave-out validation and the candidate fits of the diagnosis
        skip it, as their results serve predictions and comparisons only.
    tightening : bool
        Say, for each parameter that is not a correction node, which measurements would tighten its
        σ most (another pitch line, points further into stall or towards runaway, a channel not
        measured; :mod:`calib.calibration.tightening`): one model Jacobian per candidate group on the native BEM,
        skipped for an FMU. The refits of a leave-out validation and the candidate fits of the
        diagnosis skip it.
    identified_ratio : float
        Verdict "identified" when posterior σ <= this × prior σ.
    confounded_share : float
        Verdict "confounded" for a non-field parameter sharing at least this fraction of its
        information with the others.
    band_confidence : float
        Confidence level of the polar bands.
    band_eta : tuple of float, optional
        Spanwise positions of the polar bands (default: the η nodes).
    errors_in_variables : {"marginal", "joint", "ignore"}
        What the conditions' uncertainty does (:mod:`calib.calibration.errors_in_variables`):
        ``"joint"`` (default) estimates each point's true conditions beside the parameters (their
        measured values as priors, eliminated point by point) wherever a condition σ is stated
        (none stated, or all zero: the output-error fit, unchanged); ``"marginal"`` fits with each
        point's effective covariance R_k + J_u,k Σ_u,k J_u,kᵀ, linearized about the measured
        conditions (its 95 % intervals covered 42–56 % of the data-determined directions on the
        validation's field campaigns, the joint's 94–96 %: ``docs/validation/errors_in_variables.md``);
        ``"ignore"`` fits as if the conditions were exact (output error).
    condition_sigma : dict condition -> float, optional
        Absolute 1-σ of the measured conditions, ``wind_speed`` [m/s], ``rotor_speed`` [rpm],
        ``pitch`` [deg], >= 0; adds in quadrature to the table's ``<condition>_sigma`` columns.
    condition_relative_sigma : dict condition -> float, optional
        1-σ of the conditions as a fraction of each point's value [-] (e.g. ``{wind_speed = 0.03}``
        for a nacelle anemometer's 3 % scatter per 10-minute mean), >= 0; adds in quadrature.
    max_eiv_iterations : int
        Most fits of the marginal estimator, each with the conditions' sensitivities
        re-linearized at the last estimate (the joint estimator re-linearizes within its one fit).
    jacobian_updates : {"auto", "broyden", "model"}
        The MAP and truncated estimators' Jacobian after an accepted step of a model without exact
        derivatives (an FMU): ``"broyden"`` updates it from the step's evaluation (Broyden's rank-one update; a model
        Jacobian again when a step under it is rejected and before the estimate is final, so σ rests on
        one), ``"model"`` takes a new finite-difference Jacobian each step; ``"auto"`` (default):
        Broyden for such models. Models with exact derivatives always use the model's.
    """

    estimator: str = "map"
    sigma_bar: float | str = "auto"
    prior_sigma: float = 1.0
    prior_std: dict | None = None
    prior_correlation: float = 1.0
    cv_folds: int = 10
    cv_one_se: bool = True
    retain: str = "threshold"
    max_retained: int | None = None
    optimizer: str = "sqpmethod"
    noise: str = "known"
    sigma: dict | None = None
    relative_sigma: dict | None = None
    cd_min: float | None = 0.0
    max_relinearizations: int = 6
    max_iterations: int = 30
    max_noise_iterations: int = 10
    tolerance: float = 1e-9
    stability_cosine: float = 0.98
    representation_error: bool = True
    scale_by_fit: bool = True
    curvature_samples: int = 32
    second_start: bool = True
    prior_check: bool = True
    tightening: bool = True
    identified_ratio: float = 0.5
    confounded_share: float = 0.75
    band_confidence: float = 0.95
    band_eta: tuple | None = None
    errors_in_variables: str = "joint"
    condition_sigma: dict | None = None
    condition_relative_sigma: dict | None = None
    max_eiv_iterations: int = 10
    jacobian_updates: str = "auto"
    verbose: bool = False

    def validate(self, source: str = "CalibrationSettings", prefix: str = "") -> "CalibrationSettings":
        """Check every setting; errors name ``source`` and the key as ``prefix + name``
        (e.g. ``calibration.noise`` for a workflow file)."""
        def bad(message, key):
            raise InputError(message, source, field=f"{prefix}{key}")

        if self.noise not in NOISE_MODES:
            bad(f"unknown noise mode {self.noise!r}; valid: {', '.join(NOISE_MODES)}", "noise")
        if self.estimator not in ESTIMATORS:
            bad(f"unknown estimator {self.estimator!r}; valid: {', '.join(ESTIMATORS)}", "estimator")
        if self.jacobian_updates not in JACOBIAN_UPDATES:
            bad(f"unknown Jacobian updates {self.jacobian_updates!r}; valid: {', '.join(JACOBIAN_UPDATES)}",
                "jacobian_updates")
        if self.retain not in RETAIN_MODES:
            bad(f"unknown retain mode {self.retain!r}; valid: {', '.join(RETAIN_MODES)}", "retain")
        if isinstance(self.sigma_bar, str) and self.sigma_bar != "auto" or \
                not isinstance(self.sigma_bar, str) and not self.sigma_bar > 0:
            bad(f"must be \"auto\" or a number > 0, got {self.sigma_bar!r}", "sigma_bar")
        for key in ("prior_sigma", "tolerance"):
            if not getattr(self, key) > 0:
                bad(f"must be > 0, got {getattr(self, key)!r}", key)
        for key in ("band_confidence", "stability_cosine", "identified_ratio", "confounded_share"):
            if not 0 < getattr(self, key) <= 1:
                bad(f"must be in (0, 1], got {getattr(self, key)!r}", key)
        if not self.prior_correlation >= 0:
            bad(f"must be >= 0 (node spacings), got {self.prior_correlation!r}", "prior_correlation")
        if isinstance(self.curvature_samples, bool) or not isinstance(self.curvature_samples, int) \
                or self.curvature_samples < 0:
            bad(f"must be an integer >= 0 (prior draws; 0 leaves the term out), got {self.curvature_samples!r}",
                "curvature_samples")
        for key in ("representation_error", "scale_by_fit", "cv_one_se", "second_start", "prior_check", "tightening"):
            if not isinstance(getattr(self, key), bool):
                bad(f"must be true or false, got {getattr(self, key)!r}", key)
        for key in ("max_relinearizations", "max_iterations", "max_noise_iterations", "cv_folds"):
            if not getattr(self, key) >= 1:
                bad(f"must be >= 1, got {getattr(self, key)!r}", key)
        if self.max_retained is not None and self.max_retained < 0:
            bad(f"must be >= 0, got {self.max_retained!r}", "max_retained")
        for c, v in (self.prior_std or {}).items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0 or not np.isfinite(v):
                bad(f"must be a number > 0 (prior 1-σ in the parameter's unit), got {v!r}", f"prior_std.{c}")
        if self.sigma is not None:
            for c, v in self.sigma.items():
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
                    bad(f"must be a number > 0 (absolute 1-σ in SI units), got {v!r}", f"sigma.{c}")
        if self.noise in ("relative", "relative_ml") and not self.relative_sigma:
            bad(f"noise = \"{self.noise}\" needs relative_sigma = {{channel or group = fraction, ...}} "
                "(e.g. {torque = 0.03, thrust = 0.03, cn = 0.05})", "relative_sigma")
        for c, v in (self.relative_sigma or {}).items():
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 10:
                bad(f"must be a fraction > 0 (of the channel's RMS), got {v!r}", f"relative_sigma.{c}")
        self._validate_errors_in_variables(bad)
        try:
            get_optimizer(self.optimizer)
        except InputError as exc:
            bad(exc.message, "optimizer")
        return self

    def _validate_errors_in_variables(self, bad) -> None:
        """Check ``errors_in_variables``, the condition σ (known conditions, numbers >= 0) and
        ``max_eiv_iterations``; ``bad(message, key)`` raises."""
        if self.errors_in_variables not in ERRORS_IN_VARIABLES:
            bad(f"unknown mode {self.errors_in_variables!r}; valid: {', '.join(ERRORS_IN_VARIABLES)}",
                "errors_in_variables")
        for key, what in (("condition_sigma", "absolute 1-σ in the condition's unit: m/s, rpm, deg, kg/m^3"),
                          ("condition_relative_sigma", "a fraction of the condition's value")):
            for c, v in (getattr(self, key) or {}).items():
                if c not in UNCERTAIN_CONDITIONS:
                    bad(f"unknown condition {c!r}; valid: {', '.join(UNCERTAIN_CONDITIONS)}", f"{key}.{c}")
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not v >= 0 or not np.isfinite(v):
                    bad(f"must be a number >= 0 ({what}), got {v!r}", f"{key}.{c}")
        if not self.max_eiv_iterations >= 1:
            bad(f"must be >= 1, got {self.max_eiv_iterations!r}", "max_eiv_iterations")
