"""A calibrated model's outputs at new conditions, with intervals: :class:`Prediction`.

:func:`predict_outputs` is what :meth:`calib.calibration.result.CalibrationResult.predict` runs; the
command ``calib predict`` (:mod:`calib.calibration.predict_command`) writes its table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.calibration.discrepancy import fit_discrepancy
from calib.calibration.discrepancy_scale import discrepancy_aware_covariance
from calib.checks.envelope import envelope_of
from calib.errors import InputError


@dataclass(frozen=True, eq=False)
class Prediction:
    """Model outputs at new conditions with their intervals.

    Attributes
    ----------
    channels, units : tuple of str
    values, std, lower, upper : ndarray, shape (n_points, n_channels)
        Prediction, its 1-σ and the two-sided interval at ``confidence`` [channel units];
        NaN where ``status != 0``.
    status : ndarray of int, shape (n_points,)
    messages : tuple of str
    confidence : float
    envelope : tuple of str
        Per point, "" inside the calibration envelope, else what lies outside it
        (:func:`calib.checks.envelope.envelope_of`): an extrapolation.
    representation : str
        Whether the intervals include the correction field between and beyond the nodes
        (:func:`field_between_nodes`).
    discrepancy_std : ndarray, shape (n_points, n_channels)
        The model-discrepancy part of ``std`` (:mod:`calib.calibration.discrepancy`): zero for a
        channel the calibration fits within its noise [channel units].
    discrepancy : str
        Which channels carry a discrepancy term, in words.
    field_std : ndarray, shape (n_points, n_channels)
        The part of ``std`` from the correction field between and beyond the nodes (zero where the
        bands leave it out) [channel units]: at the stated prior's amplitude at a point inside the
        calibration envelope, at ``field_amplitude`` at a point outside it.
    field_amplitude : float
        The amplitude :func:`field_amplitude` chose for points outside the envelope, in units of the
        stated prior [-].
    condition_std : ndarray, shape (n_points, n_channels) or None
        The part of ``std`` from the conditions' uncertainty (``condition_sigma`` of
        :func:`predict_outputs`), None when the conditions are exact [channel units].
    """

    channels: tuple
    units: tuple
    values: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    status: np.ndarray
    messages: tuple
    confidence: float
    envelope: tuple = ()
    representation: str = ""
    discrepancy_std: np.ndarray | None = None
    discrepancy: str = ""
    field_std: np.ndarray | None = None
    field_amplitude: float = 1.0
    condition_std: np.ndarray | None = None

    def to_dataframe(self, conditions):
        """One row per point with its ``conditions`` (:func:`calib.calibration.frames.prediction_frame`)."""
        from calib.calibration.frames import prediction_frame
        return prediction_frame(conditions, self)

    @property
    def outside(self) -> np.ndarray:
        """True where the point lies outside the calibration envelope."""
        return np.array([bool(e) for e in self.envelope], bool) if self.envelope else \
            np.zeros(self.values.shape[0], bool)


def predict_outputs(result, conditions, model, confidence: float = 0.95,
                    condition_sigma: np.ndarray | None = None) -> Prediction:
    """Model outputs at new conditions with intervals from the estimate's covariance.

    The variance of each output is g Cov(p̂) gᵀ with g its row of the model Jacobian at p̂
    and Cov(p̂) the covariance including the frozen directions (docs/theory.md, Predictions), plus
    the model discrepancy of a channel the calibration did not fit within its noise
    (:mod:`calib.calibration.discrepancy`). Where a discrepancy applies, the MAP's Cov(p̂) is re-formed
    with the fit scale of the residuals under noise + discrepancy
    (:func:`calib.calibration.discrepancy_scale.discrepancy_aware_covariance`): the misfit is counted
    once, in the discrepancy, not also in the parameters (Kennedy & O'Hagan 2001). An interval of the
    *model output* as a description of
    the rotor, not of a new measurement (add the noise σ for that). At uncertain conditions
    (``condition_sigma``) the conditions' share diag(J_u Σ_u J_uᵀ) is added, J_u the outputs'
    sensitivities to the point's wind speed, rotor speed and pitch at p̂
    (:func:`calib.calibration.errors_in_variables.condition_sensitivities`): the first-order
    variance of the output at conditions known to within their σ (independent of the parameters'
    uncertainty).

    Parameters
    ----------
    result : CalibrationResult
    conditions : OperatingConditions
    model : ForwardModel
        The calibrated model (:meth:`calib.calibration.result.CalibrationResult.rebuild_model`).
    confidence : float
        Two-sided confidence of the intervals [-].
    condition_sigma : ndarray, shape (n_points, 4) or (n_points, 3), optional
        1-σ of each point's wind speed [m/s], rotor speed [rpm] and pitch [deg], >= 0.

    Returns
    -------
    Prediction

    Raises
    ------
    InputError
        ``condition_sigma`` of the wrong shape, negative or not finite.
    """
    from scipy import stats

    names = [c.name for c in model.channels]
    missing = [c for c in result.channels if c not in names]
    if missing:
        raise InputError(f"model lacks channel(s) {', '.join(missing)}", result.name, field="channels")
    idx = [names.index(c) for c in result.channels]
    ev, G = model.jacobian(result.estimate.p_hat, conditions)
    G = G[:, idx, :]
    rep, representation = field_between_nodes(result, model, conditions, ev, G, idx)
    unc = result.uncertainty
    disc = fit_discrepancy(result) if result.fit.measured.size else None
    est_cov = discrepancy_aware_covariance(result, disc)
    cov = est_cov.cov_p if rep is None else est_cov.cov_p - unc.cov_alias
    var = np.einsum("kcj,jl,kcl->kc", np.nan_to_num(G), cov, np.nan_to_num(G))
    values = ev.values[:, idx]
    extras = ev.extras or {}
    fit = result.fit
    envelope = envelope_of(result.conditions, result.provenance.rotor_radius, conditions.as_dict(),
                           extras.get("alpha_deg"), extras.get("eta"), fit.alpha_seen,
                           fit.eta_seen) if result.conditions else []
    outside = np.array([bool(e) for e in envelope], bool) if envelope else np.zeros(values.shape[0], bool)
    amplitude = 1.0
    if rep is not None:
        amplitude, words = field_amplitude(result)
        # beyond the calibration envelope at the amplitude the data allow; inside it at the stated prior's
        rep = np.where(outside[:, None], amplitude ** 2, 1.0) * rep
        var = var + rep
        representation = (f"{representation}; inside the calibration envelope at the stated prior's amplitude, "
                          f"outside it {words}")
    d_var = np.zeros(values.shape) if disc is None else \
        disc.variance(conditions.as_dict(), result.provenance.rotor_radius, np.nan_to_num(values))
    c_var = None
    if condition_sigma is not None:
        from calib.calibration.errors_in_variables import condition_sensitivities
        su = np.asarray(condition_sigma, float)
        from calib.calibration.settings import UNCERTAIN_CONDITIONS
        n_u = len(UNCERTAIN_CONDITIONS)
        if su.ndim == 2 and su.shape[1] == n_u - 1:     # no air-density σ: the three kinematic conditions'
            su = np.c_[su, np.zeros(su.shape[0])]
        if su.shape != (values.shape[0], n_u) or not np.all(np.isfinite(su)) or np.any(su < 0):
            raise InputError(f"condition_sigma must be {values.shape[0]} x {n_u} (or x {n_u - 1}) finite values >= 0 "
                             f"(wind speed [m/s], rotor speed [rpm], pitch [deg], air density [kg/m^3]), got shape "
                             f"{su.shape}", result.name,
                             field="condition_sigma")
        J_u, _ = condition_sensitivities(model, result.estimate.p_hat, conditions, idx, su)
        c_var = np.einsum("kcu,ku->kc", J_u ** 2, su ** 2)
        var = var + c_var
    std = np.sqrt(np.maximum(var, 0.0) + d_var)
    z = float(stats.norm.ppf(0.5 * (1 + confidence)))
    std = np.where(ev.ok[:, None], std, np.nan)
    field_std = np.sqrt(np.maximum(rep, 0.0)) if rep is not None else np.zeros(values.shape)
    return Prediction(tuple(result.channels), tuple(result.channel_units), values, std, values - z * std,
                      values + z * std, ev.status.copy(), tuple(ev.messages), confidence, tuple(envelope),
                      representation, np.where(ev.ok[:, None], np.sqrt(d_var), np.nan),
                      _discrepancy_words(disc, est_cov), np.where(ev.ok[:, None], field_std, np.nan), amplitude,
                      None if c_var is None else np.where(ev.ok[:, None], np.sqrt(c_var), np.nan))


def _discrepancy_words(disc, est_cov) -> str:
    """The discrepancy in words, with what it did to the parameters' covariance."""
    if disc is None:
        return ""
    return disc.words() + (f"; {est_cov.note}" if est_cov.note else "")


#: Largest amplitude of the field between and beyond the nodes a band carries, in units of the stated
#: prior [-]: where the data do not bound the amplitude (the prior check's interval is open above).
FIELD_AMPLITUDE_CAP = 10.0


def field_amplitude(result) -> tuple[float, str]:
    """The amplitude of the correction field between and beyond the nodes that the bands carry, in
    units of the stated prior, and a sentence on it.

    There the field is known only through its prior, and the prior's amplitude only through the
    data: the prior check (:mod:`calib.checks.prior_check`) gives its type-II maximum-likelihood
    value τ̂ and a 95 % profile-likelihood interval. Outside the calibration envelope the bands carry
    the interval's upper end, the largest amplitude the data do not reject, rather than τ̂ (which
    ignores how little the data may say about it) or the stated 1: an extrapolation into a regime the
    calibration did not see (deep stall from attached flow) widens where the data allow a larger
    field, and narrows where they call for a smaller one. Inside the envelope, where the calibration
    points pin the field, the stated prior's amplitude stays (at the bound, the in-sample predictive
    χ²/dof of the coverage twin (d) fell from 0.93 to 0.79). Chosen by measurement on band splits
    against τ̂, the stated prior, inflation by χ²/dof and a discrepancy amplitude from the nominal
    model's misfit (``benchmarks/bench_prediction.py``, docs/validation/extrapolation.md). Without a
    prior check (off, or failed) the stated prior, 1; at most :data:`FIELD_AMPLITUDE_CAP`.
    """
    pc = result.uncertainty.prior_check or {}
    if not pc or pc.get("failed") or "upper" not in pc:
        why = "failed" if pc.get("failed") else "not run"
        return 1.0, f"at the stated prior's amplitude (the prior check {why})"
    upper = float(pc["upper"])
    if not np.isfinite(upper) or upper > FIELD_AMPLITUDE_CAP:
        return FIELD_AMPLITUDE_CAP, (f"at {FIELD_AMPLITUDE_CAP:g} × the stated prior's amplitude: the data do not "
                                     f"bound it (prior check τ̂ = {float(pc['amplitude']):.2g}, interval open above)")
    return upper, (f"at {upper:.2g} × the stated prior's amplitude, the largest the data allow (prior check "
                   f"τ̂ = {float(pc['amplitude']):.2g}, 95 % interval {float(pc['lower']):.2g}–{upper:.2g})")


def field_between_nodes(result, model, conditions, ev, G, idx) -> tuple[np.ndarray | None, str]:
    """The variance of each predicted output [channel unit²] from the correction field the nodes do
    not carry (between them, and beyond their range, where it is the prior's), net of what the
    estimate took up of it at the calibration points, and a sentence on it.

    With the smooth-field prior, the field is f = Σ N_i f_i + δ, δ ~ N(0, Σ_δ) on a fine grid
    (:mod:`calib.parametrizations.aliasing`). A predicted output y = g p + w δ and the estimate
    p̂ = p + K(W_cal δ + noise) (K = ``gain``, the MAP's linear response to the whitened data),
    so its error has the δ-part (g K W_cal − w) δ, of variance (gK W_cal − w) Σ_δ (gK W_cal − w)ᵀ;
    that replaces the nodal term g Cov_alias gᵀ in g Cov(p̂) gᵀ. Beyond the nodes the hats vanish
    and δ is the whole field: the correction reverts to the prior's band there. None when the
    result has no gain (truncated estimator, no field) or the model cannot be refined (an FMU).
    """
    st = result.provenance.settings
    unc, fit, est = result.uncertainty, result.fit, result.estimate
    if not unc.gain.size or not unc.prior_std.size:
        return None, ("the bands leave out the field between and beyond the correction nodes (estimator "
                      f"{st.get('estimator', 'truncated')!r} records no gain)")
    if not model.capabilities.refinable or not st.get("representation_error", True) \
            or not st.get("prior_correlation", 0.0) > 0:
        return None, "the bands leave out the field between and beyond the correction nodes (off, or not refinable)"
    from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities
    from calib.types import OperatingConditions

    field_ = model.correction_field()
    a_new, e_new = field_.seen(ev)
    cal = OperatingConditions(**result.conditions)
    a_all, e_all = np.concatenate([a_new, fit.alpha_seen]), np.concatenate([e_new, fit.eta_seen])
    ok_cal = fit.status_after == 0
    ones = np.ones((len(conditions), len(idx)))
    fs_new = fine_sensitivities(model, est.p_hat, conditions, ones, idx, ev.ok, a_all, e_all)
    fs_cal = fine_sensitivities(model, est.p_hat, cal, fit.sigma, idx, ok_cal, a_all, e_all)
    gG = np.nan_to_num(G).reshape(-1, G.shape[-1]) * est.scale       # ∂y/∂p̃ per output row
    A = gG @ (unc.gain @ fs_cal.W) - fs_new.W
    var = discrepancy_propagated(A, field_, fs_new, unc.prior_std, float(st["prior_correlation"]), diagonal=True)
    return var.reshape(G.shape[:2]), ("the bands include the field between and beyond the correction nodes "
                                      "(the prior's, net of what the calibration points determined)")
