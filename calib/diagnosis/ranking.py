"""The statistics that rank candidate effects against the model without them (docs/theory.md,
Diagnosis): the likelihood ratio and its p-value (:func:`likelihood_ratio`), the BIC
weights (:func:`set_bic_weights`) and the agreement of a candidate's pattern with the localized
correction (:func:`pattern_agreement`).

References
----------
S.S. Wilks, The large-sample distribution of the likelihood ratio for testing composite
hypotheses, Ann. Math. Stat. 9 (1938) 60-62.
G. Schwarz, Estimating the dimension of a model, Ann. Stat. 6 (1978) 461-464.
K.P. Burnham, D.R. Anderson, Model Selection and Multimodel Inference, 2nd ed., Springer (2002).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from calib.diagnosis.result import CandidateFit


def likelihood_ratio(chi2_base: float, chi2: float, k: int) -> tuple[float, float]:
    """The likelihood-ratio statistic of a candidate and its p-value.

    Parameters
    ----------
    chi2_base, chi2 : float
        χ² of the model without and with the candidate [-].
    k : int
        The candidate's parameter count.

    Returns
    -------
    lr : float
        Λ = χ²_base − χ², not below 0 [-].
    p_value : float
        P(χ²(k) ≥ Λ), the chance of a Λ as large when the candidate adds nothing (Wilks 1938);
        1 without parameters.
    """
    lr = max(chi2_base - chi2, 0.0)
    p = float(stats.chi2.sf(lr, k)) if k else 1.0
    return lr, p


def pattern_agreement(change: np.ndarray, field_change: np.ndarray) -> float:
    """Correlation of a candidate's change of the outputs with the localized correction's [-].

    Parameters
    ----------
    change, field_change : ndarray, shape (n_points, n_channels)
        The whitened changes of the outputs by the candidate and by the free correction field,
        both from the current model [-].

    Returns
    -------
    float
        The correlation over the finite entries; NaN with fewer than three of them or when
        either change is constant there.
    """
    a, b = change.reshape(-1), field_change.reshape(-1)
    good = np.isfinite(a) & np.isfinite(b)
    return float(np.corrcoef(a[good], b[good])[0, 1]) if good.sum() > 2 and np.std(a[good]) > 0 and \
        np.std(b[good]) > 0 else float("nan")


def set_bic_weights(fits: list[CandidateFit], chi2_base: float) -> None:
    """Set each candidate's BIC weight w ∝ exp(−½ BIC), normalized over the candidates and
    "none" (the model without them, BIC = ``chi2_base`` [-]) (Schwarz 1978; Burnham & Anderson 2002)."""
    bics = np.array([f.bic for f in fits] + [chi2_base])
    wts = np.exp(-0.5 * (bics - bics.min()))
    wts /= wts.sum()
    for f, wgt in zip(fits, wts[:-1]):
        f.weight = float(wgt)
