"""The correction field between and beyond the nodes as a covariance across the power-curve bins.

:func:`calib.calibration.prediction.predict_outputs` gives the field's 1-σ per point; an integral
quantity such as the AEP needs its covariance across the bins. The field is one function of
(α, η): neighbouring bins see it at nearby angles of attack, so their errors are correlated, but not
perfectly (bins in attached flow and bins near stall see different parts of it, and the estimate's
response to it at the calibration points can cancel part of it at one bin and not at another).
Adding the per-bin σ linearly over the bins (perfect correlation) is only an upper bound
(Cauchy-Schwarz); adding them in quadrature (independence) a lower one. :func:`field_covariance`
gives the full matrix, from the same quantities as ``predict_outputs``.

Notes
-----
With the smooth-field prior the field is f = Σ N_i f_i + δ, δ ~ N(0, Σ_δ) on a fine grid
(:mod:`calib.parametrizations.aliasing`). A predicted output y_k = g_k p + w_k δ and the MAP estimate
p̂ = p + K (W_cal δ + noise) (K the MAP's gain, ``result.uncertainty.gain``), so the δ-part of the
errors of all bins is A δ with A = G K W_cal − W_new, of covariance A Σ_δ Aᵀ
(:func:`calib.parametrizations.aliasing.discrepancy_propagated` with ``diagonal=False``); its diagonal is
``predict_outputs``' ``field_std``² (a test checks it). That term replaces the nodal aliasing term
g Cov_alias gᵀ of g Cov(p̂) gᵀ (Kennedy & O'Hagan 2001, the model discrepancy as a Gaussian
process; here the field's between-node part), so the parameter draws that go with it come from
Cov(p̂) − Cov_alias, as ``predict_outputs`` does.
"""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["field_covariance"]


def field_covariance(result, model, conditions: OperatingConditions, channel: str) -> np.ndarray | None:
    """Covariance across the points of ``channel`` from the correction field between and beyond the
    nodes, net of what the estimate took up of it [channel unit²], at the stated prior's amplitude.

    Parameters
    ----------
    result : CalibrationResult
    model : BemModel
        With the result's channels (:func:`calib.calibration.prediction.predict_outputs` needs the same).
    conditions : OperatingConditions
        The points (the power-curve bins at the central schedule).
    channel : str
        One of the result's channels (``"power"`` or ``"torque"``).

    Returns
    -------
    ndarray, shape (n_points, n_points) or None
        None where ``predict_outputs`` leaves the term out (truncated estimator, no gain, no field, a
        model that cannot be refined, ``representation_error`` off, independent nodes); zero rows and
        columns where a point failed.
    """
    st = result.provenance.settings
    unc, fit, est = result.uncertainty, result.fit, result.estimate
    if not unc.gain.size or not unc.prior_std.size or not st.get("representation_error", True) \
            or not st.get("prior_correlation", 0.0) > 0 or not model.capabilities.refinable:
        return None
    from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities

    names = [c.name for c in model.channels]
    idx = [names.index(c) for c in result.channels]
    one = [names.index(channel)]
    ev, G = model.jacobian(est.p_hat, conditions)
    field_ = model.correction_field()
    a_new, e_new = field_.seen(ev)
    cal = OperatingConditions(**result.conditions)
    a_all, e_all = np.concatenate([a_new, fit.alpha_seen]), np.concatenate([e_new, fit.eta_seen])
    # the same fine grid as predict_outputs (it refines over every channel's points, the same α and η)
    fs_new = fine_sensitivities(model, est.p_hat, conditions, np.ones((len(conditions), 1)), one, ev.ok, a_all, e_all)
    fs_cal = fine_sensitivities(model, est.p_hat, cal, fit.sigma, idx, fit.status_after == 0, a_all, e_all)
    g = np.nan_to_num(G[:, one[0], :]) * est.scale
    A = g @ (unc.gain @ fs_cal.W) - fs_new.W
    cov = discrepancy_propagated(A, field_, fs_new, unc.prior_std, float(st["prior_correlation"]), diagonal=False)
    ok = ev.ok
    return np.where(ok[:, None] & ok[None, :], 0.5 * (cov + cov.T), 0.0)


def prior_split(result, model, cov: np.ndarray) -> dict | None:
    """The nodal covariance ``cov`` (Cov(p̂) − Cov_alias of a MAP result) split over the directions
    of the prior-whitened posterior, and its value at another prior amplitude of the field.

    The MAP's Laplace covariance is C = (H + P⁻¹)⁻¹ (H the data's information at the estimate, the
    noise widened by the fit scale; P the stated prior, ``prior_std`` with the field's correlation;
    :func:`calib.calibration.uncertainty.laplace_covariance`). In the prior-whitened coordinates
    B = P^-½ C P^-½ = (Ĥ + I)⁻¹ = U diag(b) Uᵀ: a direction with b ≥ ½ is prior-dominated (the data
    carry less information on it than the prior, s² ≤ 1, the same split as the calibration's
    ``weak`` directions), one with b < ½ data-determined. With the field's prior amplitude τ instead
    of 1 (the empirical-Bayes alternative, τ̂ of the prior check, :mod:`calib.checks.prior_check`;
    Rasmussen & Williams 2006, §5.4) the nodal covariance is
    C_τ = P^½ (Ĥ + T⁻²)⁻¹ P^½, T = τ on the field's nodes and 1 on the other parameters (T
    commutes with P^½: the prior is block-diagonal), with p̂ kept (the MAP of the stated prior).

    Returns
    -------
    dict or None
        ``half`` (P^½ U, shape (n, n)), ``b`` (n,), ``U`` (n, n), ``field`` (bool mask of the field's
        parameters), ``tau`` (τ̂) and ``tau_lower``/``tau_upper`` (its 95 % interval); None for
        another estimator than MAP, without a prior check or without a correction field.
    """
    st = result.provenance.settings
    pc = result.uncertainty.prior_check or {}
    if st.get("estimator") != "map" or not pc or pc.get("failed") or "amplitude" not in pc:
        return None
    try:
        fld = model.correction_field() if hasattr(model, "correction_field") else None
    except (AttributeError, ValueError, InputError):        # a model without a correction field
        fld = None
    if fld is None or getattr(fld, "grid", None) is None:
        return None
    sd = np.asarray(result.uncertainty.prior_std, float)
    if sd.size != cov.shape[0] or not np.all(sd > 0):
        return None
    C = fld.node_correlation(float(st.get("prior_correlation", 0.0)))
    if C.shape != cov.shape:
        return None
    mask = np.zeros(cov.shape[0], bool)
    lay = fld.layout
    for idx in (lay.lift_index, lay.drag_index):
        mask[idx[idx >= 0].ravel()] = True
    return split_covariance(cov, sd, C, mask, float(pc["amplitude"]), float(pc.get("lower", np.nan)),
                            float(pc.get("upper", np.nan)))


def split_covariance(cov, prior_std, correlation, field_mask, tau: float = 1.0, tau_lower: float = np.nan,
                     tau_upper: float = np.nan) -> dict:
    """:func:`prior_split` from its parts: the Laplace covariance ``cov`` = (H + P⁻¹)⁻¹ [parameter
    units²], the prior 1-σ ``prior_std`` [parameter units] and correlation ``correlation`` (P = D C D,
    block-diagonal), the field's parameters ``field_mask`` and the prior check's amplitude."""
    cov = np.asarray(cov, float)
    sd = np.asarray(prior_std, float)
    w, V = np.linalg.eigh(np.asarray(correlation, float))
    Ch = (V * np.sqrt(np.clip(w, 0.0, None))) @ V.T                # C^½ (symmetric)
    Chi = (V / np.sqrt(np.clip(w, 1e-12, None))) @ V.T
    # P = D C D = (D C^½)(D C^½)ᵀ: whiten with (D C^½)⁻¹ = C^-½ D⁻¹ on the left, its transpose on the right
    Ph, Pmh = sd[:, None] * Ch, Chi / sd[None, :]
    Bm = Pmh @ cov @ Pmh.T
    b, U = np.linalg.eigh(0.5 * (Bm + Bm.T))
    b = np.clip(b, 1e-12, 1.0)
    return {"half": Ph @ U, "b": b, "U": U, "field": np.asarray(field_mask, bool), "tau": float(tau),
            "tau_lower": float(tau_lower), "tau_upper": float(tau_upper)}


def split_variance(split: dict, g: np.ndarray) -> dict:
    """Var(g·p̂) of a linear functional ``g`` [quantity per parameter unit] by the directions of
    :func:`prior_split`: ``data`` (b < ½), ``prior`` (b ≥ ½) [quantity²]."""
    proj = (np.asarray(g, float) @ split["half"]) ** 2 * split["b"]
    weak = split["b"] >= 0.5
    return {"data": float(proj[~weak].sum()), "prior": float(proj[weak].sum())}


def variance_at_amplitude(split: dict, g: np.ndarray, tau: float) -> float:
    """Var(g·p̂) [quantity²] under the field's prior amplitude ``tau`` (:func:`prior_split`)."""
    U, b = split["U"], split["b"]
    Hh = (U * (1.0 / b - 1.0)) @ U.T
    t = np.where(split["field"], max(float(tau), 1e-6), 1.0)
    # in the whitened coordinates of P = (D C^½)(D C^½)ᵀ the field's T is diagonal only when C^½
    # keeps the blocks apart, which it does (C is block-diagonal, C^½ too)
    Ct = np.linalg.inv(Hh + np.diag(1.0 / t ** 2))
    a = np.asarray(g, float) @ (split["half"] @ U.T)      # g P^½
    return float(a @ Ct @ a)
