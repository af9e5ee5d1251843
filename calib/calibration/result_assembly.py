"""The :class:`calib.calibration.result.CalibrationResult` of a finished calibration, part by part.

:func:`assemble_result` builds each part (:mod:`calib.calibration.result_parts`) from the calibrator's state
and the estimator's covariance; the calibrator (:class:`calib.calibration.calibrator.Calibrator`) calls it
once, at the end of either estimator.
"""

from __future__ import annotations

from dataclasses import asdict, fields, replace

import numpy as np

from calib.calibration.identifiability import confounding, cramer_rao, fisher_matrix, parameter_verdicts
from calib.calibration.result import CalibrationResult
from calib.calibration.result_parts import PARTS, Estimate, Fit, Identifiability, Provenance, Uncertainty
from calib.calibration.uncertainty_terms import ModelTerms
from calib.errors import InputError


def assemble_result(terms: ModelTerms, problem, nominal, lin, svd, cov_p, cov_frozen, cov_theta, theta_hat, obs,
                    status, message, wall, **extra) -> CalibrationResult:
    """The :class:`CalibrationResult` of either estimator.

    Parameters
    ----------
    terms : ModelTerms
        The problem statement and its model-derived terms.
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
        The result's other fields, each put into the part that has a field of that name
        (:func:`_into_parts`): the estimator's own, and the calibrator's (``history``,
        ``truncation``, ``name``).
    """
    m, statement = terms.measurements, terms.statement
    radius, spec = _model_record(terms.model)
    fit = _fit_part(terms, problem, nominal, lin)     # the failures counted before the tightening's probes
    extra.setdefault("tightening", terms.tightening(problem, lin, cov_p, radius))
    units = [terms.model.channels[i].unit for i in statement.channel_index]
    res = CalibrationResult(
        parameters=[asdict(q) for q in statement.parameters], channels=list(m.channels), channel_units=units,
        conditions=m.conditions.as_dict(),
        estimate=Estimate(statement.p0, lin.p, statement.lower, statement.upper, statement.scale, theta_hat,
                          status, message),
        identifiability=_identifiability(terms, lin, svd, cov_p, obs),
        uncertainty=Uncertainty(cov_p, np.sqrt(np.maximum(np.diag(cov_p), 0.0)), cov_theta, statement.prior_std,
                                cov_frozen),
        fit=fit,
        provenance=Provenance(_settings_record(terms), spec, radius, wall_time=wall,
                              inputs={m.source: m.sha256} if m.sha256 else {}))
    res = _into_parts(res, extra)
    st, field = terms.settings, terms.field
    if field is not None and field.grid is not None:
        res.uncertainty.polar_bands = field.bands(
            lin.p, cov_p, cov_frozen, eta=st.band_eta, confidence=st.band_confidence,
            prior_std=statement.prior_std if st.representation_error else None,
            correlation_length=st.prior_correlation, cd_min=st.cd_min)
    return res


def _identifiability(terms: ModelTerms, lin, svd, cov_p, obs) -> Identifiability:
    """The result's identifiability part: the directions, the Cramér–Rao figures and the verdicts
    (the truncation record is the calibrator's to add)."""
    st, statement = terms.settings, terms.statement
    F = fisher_matrix(lin.M)
    _, crb_std_scaled, corr = cramer_rao(F)
    conf = confounding(F, statement.prior_std / statement.scale, statement.parameters)
    std_p = np.sqrt(np.maximum(np.diag(cov_p), 0.0))
    verdicts = parameter_verdicts(statement.parameters, lin.p, statement.lower, statement.upper, std_p,
                                  statement.prior_std, obs, conf, st.identified_ratio, st.confounded_share)
    return Identifiability(svd.singular_values, svd.V, svd.sigma_theta, svd.retained, float(svd.sigma_bar),
                           corr, crb_std_scaled * statement.scale, obs, verdicts, conf)


def _fit_part(terms: ModelTerms, problem, nominal, lin) -> Fit:
    """The result's fit part: the model before and after against the measurements, χ², failures."""
    m = terms.measurements
    before = nominal.evaluation.values[:, terms.statement.channel_index]
    ev = lin.evaluation
    alpha_seen, eta_seen = terms.field.seen(ev) if terms.field is not None else (np.zeros(0), np.zeros(0))
    failures = {"nominal": nominal.n_failed, "final": lin.n_failed,
                "total_failed_point_evaluations": problem.n_failed_points_total,
                "model_evaluations": problem.n_evaluations, "model_jacobians": problem.n_jacobians}
    return Fit(m.values, problem.sigma, before, ev.values[:, terms.statement.channel_index], nominal.evaluation.status,
               ev.status, problem.sigma[0],
               float(np.sum(((m.values - before)[nominal.ok] / problem.sigma[nominal.ok]) ** 2)),
               float(np.sum(lin.residual[lin.ok] ** 2)), alpha_seen, eta_seen, failures=failures)


def _model_record(model) -> tuple[float | None, dict | None]:
    """The rotor radius [m] and the spec that rebuilds the model, (None, None) when it cannot be rebuilt."""
    if not model.capabilities.rebuildable:
        return None, None
    try:
        return model.rotor_radius, model.spec()
    except InputError:
        return model.rotor_radius, None


def _settings_record(terms: ModelTerms) -> dict:
    """The settings as the result records them: the model's name and the effective lower bounds added."""
    settings = asdict(terms.settings)
    settings["model"] = terms.model.capabilities.name
    settings["lower_effective"] = terms.statement.lower.tolist()
    return settings


def _into_parts(res: CalibrationResult, extra: dict) -> CalibrationResult:
    """``res`` with each value of ``extra`` set in the part that has a field of its name (``name``
    on the result itself); a name no part has is an error of the caller."""
    extra = dict(extra)
    own = {k: extra.pop(k) for k in ("name",) if k in extra}
    parts = {}
    for part, cls in PARTS.items():
        mine = {f.name: extra.pop(f.name) for f in fields(cls) if f.name in extra}
        if mine:
            parts[part] = replace(getattr(res, part), **mine)
    if extra:
        raise TypeError(f"no part of a result has the field(s) {', '.join(sorted(extra))}")
    return res.replace(**own, **parts)
