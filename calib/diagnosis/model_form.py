"""Model form against physical effects in the naming rounds (issue 37, items 3-4): whether a
physical effect can be told from the model-form parameters named before it.

A model-form parameter (``Effect.kind = "model_form"``: the BEM's own induction model, e.g.
``tip_loss``, ``momentum_balance``) that is named takes up the misfit of the induction model's
form. A physical effect fitted on top of it whose parameters move the loads the same way (their
squared multiple correlation with the named model-form parameters, from the Cramér–Rao
correlation of the joint fit, i.e. in the Fisher metric, at or above
:data:`MODEL_FORM_COLLINEARITY`) cannot be told from that form by these data: it is reported
as not separable from model form, not named. Used by :class:`calib.diagnosis.naming.Namer`.
"""

from __future__ import annotations

import numpy as np

#: Collinearity with the model form named so far above which a physical effect is "not separable
#: from model form" and not named [-]: the squared multiple correlation (Cramér–Rao, i.e. in the
#: Fisher metric of the joint fit) of each of the effect's parameters with the named model-form
#: parameters, all of them at or above it. Measured (2026-11-27, NREL 5-MW, the battery's 63 points,
#: on top of momentum_balance and tip_loss; lifting-line fast-wake control seeds 26008-26009):
#: wind_tunnel_blockage 0.93-0.94, wind_speed_scale 0.84-0.88, lift_offset 0.85 (they move the
#: loads as the induction model's strength does); pitch_offset 0.30-0.46, rotational augmentation
#: 0.01-0.41, reynolds_number 0.01-0.45, erosion's onset 0.01-0.15. A correlation of 0.8 halves
#: the Fisher information left to the effect five times over (1 − R² = 0.2).
MODEL_FORM_COLLINEARITY = 0.8


def model_form_r2(correlation, base: list, own: list) -> np.ndarray | None:
    """Squared multiple correlation of each parameter in ``own`` with the model-form parameters
    of ``base`` [-].

    Parameters
    ----------
    correlation : ndarray, shape (n, n), or None
        Cramér–Rao correlation of the joint fit's parameters (base effects first, then the
        candidate's: ``CalibrationResult.identifiability.correlation``).
    base : list of (parameters, kind)
        Each base effect's parameters (in the fit's order) and its kind ("model_form" or
        "physical").
    own : list of int
        Indices of the candidate's parameters.

    Returns
    -------
    ndarray, shape (len(own),), or None
        R²_j = 1 − 1 / (C⁻¹)_jj over the sub-matrix of the model-form parameters and j (the
        variance inflation of j from the model form; Belsley, Kuh & Welsch, Regression
        Diagnostics, Wiley 1980, ch. 3); NaN where it cannot be formed; None when no model form
        is in ``base`` or no correlation is known.
    """
    idx, k = [], 0
    for params, kind in base:
        n = len(params)
        if kind == "model_form":
            idx += list(range(k, k + n))
        k += n
    if not idx or correlation is None:
        return None
    corr = np.asarray(correlation, float)
    out = []
    for j in own:
        sub = idx + [j]
        with np.errstate(all="ignore"):
            try:
                out.append(1.0 - 1.0 / np.linalg.inv(corr[np.ix_(sub, sub)])[-1, -1])
            except np.linalg.LinAlgError:
                out.append(np.nan)
    return np.array(out, float)


def not_separable(r2, best, model_form: list) -> str | None:
    """The reason ``best`` (a physical candidate's fit) is not named, or None when it is separable.

    Not separable: every parameter's R² (:func:`model_form_r2`) at or above
    :data:`MODEL_FORM_COLLINEARITY`; an unknown or non-finite R² counts as separable (the
    other rules decide).
    """
    if r2 is None or len(r2) == 0 or not np.all(np.isfinite(r2)) or float(np.min(r2)) < MODEL_FORM_COLLINEARITY:
        return None
    form = ", ".join(model_form)
    many = len(r2) > 1
    return (f"{best.name} is not separable from model form: its parameter{'s' if many else ''} "
            f"correlate{'' if many else 's'} with {form} at R² = {', '.join(f'{v:.2f}' for v in r2)} (at least "
            f"{MODEL_FORM_COLLINEARITY:g} is not separable), so its fit (Λ = {best.lr_statistic:.4g}, "
            f"{best.effect_text}) cannot tell a missing effect from the form of {form}: not named")
