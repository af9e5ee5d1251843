"""The marginal errors-in-variables estimator's prototypes of ``benchmarks/bench_eiv_marginal.py`` (issue 40):
the records' mean over their condition errors by the two-point Gauss rule, and a model whose output is that
mean. PROTOTYPES, outside the library, for an experiment: not a default, not part of ``calib``."""

from __future__ import annotations

import dataclasses

import numpy as np

from calib.models.base import Capabilities
from calib.types import Evaluation, OperatingConditions


def with_conditions(conditions: OperatingConditions, **values) -> OperatingConditions:
    """``conditions`` with the named fields replaced."""
    return dataclasses.replace(conditions, **values)


def mean_correction(evaluate, conditions: OperatingConditions, sigma: np.ndarray) -> tuple[list, np.ndarray]:
    """The two-point Gauss rule of E[y(u + e)] − y(u), e ~ N(0, diag σ²), over wind speed and pitch.

    c(u) = Σ_d ½ [y(u + σ_d e_d) + y(u − σ_d e_d) − 2 y(u)] (exact for outputs cubic in each condition;
    the cross terms vanish for independent errors).

    Parameters
    ----------
    evaluate : callable
        conditions -> any result (outputs, an Evaluation, ...); called at the shifted conditions.
    conditions : OperatingConditions
    sigma : ndarray, shape (n_points, 2)
        1-σ of wind speed [m/s] and pitch [deg].

    Returns
    -------
    results : list
        ``evaluate``'s results at u + σ_V, u − σ_V, u + σ_β, u − σ_β.
    weights : ndarray
        Of the four results: c = Σ_i w_i y_i − (Σ_i w_i) y(u) = Σ_i w_i y_i − 2 y(u).
    """
    shifted = []
    for j, name in ((0, "wind_speed"), (1, "pitch")):
        u = getattr(conditions, name)
        shifted += [with_conditions(conditions, **{name: u + sigma[:, j]}), with_conditions(conditions, **{name: u - sigma[:, j]})]
    return [evaluate(c) for c in shifted], np.full(4, 0.5)


class MeanCorrectedModel:
    """PROTOTYPE (issue 40, not in the library): a model whose output is its mean over the records'
    condition errors, ȳ(p, u) = y(p, u) + c(p, u) (:func:`mean_correction`), its Jacobian the same
    combination of the model's. Built for one campaign: ``sigma`` holds its records' stated σ of the
    wind reading [m/s] and pitch [deg], so it evaluates batches of exactly those records."""

    def __init__(self, model, sigma: np.ndarray, centre_wind: bool = False):
        self._model = model
        self._sigma = np.asarray(sigma, float)
        self._centre_wind = centre_wind

    def _centred(self, conditions: OperatingConditions) -> OperatingConditions:
        """With ``centre_wind``: each wind reading V̄ moved to E[V | V̄] = V̄ (1 + 2 r²), r = σ_V / V̄ its stated
        relative σ (a reading V̄ = V (1 + r ε) of a true V spread flatly about it)."""
        if not self._centre_wind:
            return conditions
        r = self._sigma[:, 0] / conditions.wind_speed
        return with_conditions(conditions, wind_speed=conditions.wind_speed * (1.0 + 2.0 * r ** 2))

    def __getattr__(self, name):
        return getattr(self._model, name)

    @property
    def capabilities(self) -> Capabilities:
        """The model's, not refinable (its ``with_grid`` would drop the mean)."""
        return dataclasses.replace(self._model.capabilities, refinable=False)

    def _check(self, conditions):
        if len(conditions) != len(self._sigma):
            raise ValueError(f"MeanCorrectedModel holds the σ of {len(self._sigma)} records, got {len(conditions)}")

    @staticmethod
    def _combine(centre: Evaluation, shifted: list, values: list, weights) -> tuple[Evaluation, np.ndarray]:
        ok = centre.ok.copy()
        for ev in shifted:
            ok &= ev.ok
        mean = (1.0 - weights.sum()) * values[0] + sum(w * v for w, v in zip(weights, values[1:]))
        status = np.where(ok | ~centre.ok, centre.status, np.max([ev.status for ev in shifted], axis=0))
        return dataclasses.replace(centre, status=status), mean

    def evaluate(self, p, conditions: OperatingConditions) -> Evaluation:
        self._check(conditions)
        conditions = self._centred(conditions)
        centre = self._model.evaluate(p, conditions)
        shifted, w = mean_correction(lambda c: self._model.evaluate(p, c), conditions, self._sigma)
        ev, mean = self._combine(centre, shifted, [centre.values] + [e.values for e in shifted], w)
        return dataclasses.replace(ev, values=np.where(ev.ok[:, None], mean, np.nan))

    def jacobian(self, p, conditions: OperatingConditions):
        self._check(conditions)
        conditions = self._centred(conditions)
        centre, G = self._model.jacobian(p, conditions)
        pairs, w = mean_correction(lambda c: self._model.jacobian(p, c), conditions, self._sigma)
        shifted = [e for e, _ in pairs]
        ev, mean = self._combine(centre, shifted, [centre.values] + [e.values for e in shifted], w)
        _, Gm = self._combine(centre, shifted, [G] + [g for _, g in pairs], w)
        ev = dataclasses.replace(ev, values=np.where(ev.ok[:, None], mean, np.nan))
        return ev, np.where(ev.ok[:, None, None], Gm, np.nan)
