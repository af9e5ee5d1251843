"""The :class:`calib.result.CalibrationResult` of a finished calibration, part by part.

:func:`assemble_result` builds each part (:mod:`calib.result_parts`) from the calibrator's state
and the estimator's covariance; the calibrator (:class:`calib.calibration.Calibrator`) calls it
once, at the end of either estimator.
"""

from __future__ import annotations

from dataclasses import asdict

import numpy as np

from calib.errors import InputError
from calib.identifiability import confounding, cramer_rao, fisher_matrix, parameter_verdicts
from calib.result import CalibrationResult
from calib.result_parts import Estimate, Fit, Identifiability, Provenance, Uncertainty


def assemble_result(cal, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs, status, message,
                    wall, **extra) -> CalibrationResult:
    """The :class:`CalibrationResult` of either estimator.

    Parameters
    ----------
    cal : Calibrator
        The calibrator that ran (its problem statement, prior, history and model terms).
    problem, nominal, lin : LeastSquaresProblem, its evaluation at nominal, its linearization at p̂
    svd : SvdAnalysis
        The directions (truncated: retained θ; MAP: the prior-whitened directions).
    cov_p, cov_frozen : ndarray, shape (n, n)
        The covariance of p̂ and its part the prior, not the data, determines [parameter units²].
    cov_theta, theta_hat : ndarray
        Covariance [scale units²] and values [scale units] of the determined directions' coordinates.
    obs : ndarray, shape (n,)
        Observability of each parameter [-].
    status, message : str
        How the estimator ended.
    wall : float
        Duration [s].
    **extra
        The estimator's own fields of the result's parts, by flat name.
    """
    m = cal.measurements
    radius, spec = _model_record(cal)
    fit = _fit_part(cal, problem, nominal, lin)     # the failures counted before the tightening's probes
    extra.setdefault("tightening", cal.terms.tightening(problem, lin, cov_p, radius))
    res = CalibrationResult(
        parameters=[asdict(q) for q in cal.parameters], channels=list(m.channels),
        channel_units=cal.channel_units, conditions=m.conditions.as_dict(),
        estimate=Estimate(cal.p0, lin.p, cal.lower, cal.upper, cal.scale, theta_hat, status, message,
                          cal.history),
        identifiability=_identifiability(cal, lin, svd, cov_p, obs),
        uncertainty=Uncertainty(cov_p, np.sqrt(np.maximum(np.diag(cov_p), 0.0)), cov_theta, cal.prior_std,
                                cov_frozen),
        fit=fit,
        provenance=Provenance(_settings_record(cal), spec, radius, wall_time=wall,
                              inputs={m.source: m.sha256} if m.sha256 else {}),
        name=cal.name).replace(**extra)
    st = cal.settings
    if cal.field is not None and cal.field.grid is not None:
        res.uncertainty.polar_bands = cal.field.bands(
            lin.p, cov_p, cov_frozen, eta=st.band_eta, confidence=st.band_confidence,
            prior_std=cal.prior_std if st.representation_error else None,
            correlation_length=st.prior_correlation, cd_min=st.cd_min)
    return res


def _identifiability(cal, lin, svd, cov_p, obs) -> Identifiability:
    """The result's identifiability part: the directions, the Cramér–Rao figures, the verdicts
    and the truncation curve (empty for an explicit σ̄ or with every parameter kept)."""
    st = cal.settings
    F = fisher_matrix(lin.M)
    _, crb_std_scaled, corr = cramer_rao(F)
    conf = confounding(F, cal.prior_std / cal.scale, cal.parameters)
    std_p = np.sqrt(np.maximum(np.diag(cov_p), 0.0))
    verdicts = parameter_verdicts(cal.parameters, lin.p, cal.lower, cal.upper, std_p, cal.prior_std, obs,
                                  conf, st.identified_ratio, st.confounded_share)
    curve = cal.truncation.curve
    truncation = curve.to_dict() if curve is not None and st.sigma_bar == "auto" and st.retain != "all" else {}
    if truncation and cal._second_start_record:
        truncation.update(cal._second_start_record)
    return Identifiability(svd.singular_values, svd.V, svd.sigma_theta, svd.retained, float(svd.sigma_bar),
                           corr, crb_std_scaled * cal.scale, obs, verdicts, conf, truncation)


def _fit_part(cal, problem, nominal, lin) -> Fit:
    """The result's fit part: the model before and after against the measurements, χ², failures."""
    m = cal.measurements
    before = nominal.evaluation.values[:, cal.channel_index]
    ev = lin.evaluation
    alpha_seen, eta_seen = cal.field.seen(ev) if cal.field is not None else (np.zeros(0), np.zeros(0))
    failures = {"nominal": nominal.n_failed, "final": lin.n_failed,
                "total_failed_point_evaluations": problem.n_failed_points_total,
                "model_evaluations": problem.n_evaluations, "model_jacobians": problem.n_jacobians}
    return Fit(m.values, problem.sigma, before, ev.values[:, cal.channel_index], nominal.evaluation.status,
               ev.status, problem.sigma[0],
               float(np.sum(((m.values - before)[nominal.ok] / problem.sigma[nominal.ok]) ** 2)),
               float(np.sum(lin.residual[lin.ok] ** 2)), alpha_seen, eta_seen, failures=failures)


def _model_record(cal) -> tuple[float | None, dict | None]:
    """The rotor radius [m] and the spec that rebuilds the model, (None, None) when it cannot be rebuilt."""
    if not cal.model.capabilities.rebuildable:
        return None, None
    try:
        return cal.model.rotor_radius, cal.model.spec()
    except InputError:
        return cal.model.rotor_radius, None


def _settings_record(cal) -> dict:
    """The settings as the result records them: the model's name and the effective lower bounds added."""
    settings = asdict(cal.settings)
    settings["model"] = cal.model.capabilities.name
    settings["lower_effective"] = cal.lower.tolist()
    return settings
