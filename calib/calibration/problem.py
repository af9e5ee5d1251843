r"""The calibration problem: its statement, built once by the Calibrator and read by the estimators,
the uncertainty terms and the result (the parameters, their nominal values, scales, effective
bounds and prior, and the measured channels' columns: :class:`ProblemStatement`); the problem as
the estimators see it, the statement with the model, the measured outputs and their noise
(:class:`LeastSquaresProblem`); and the model linearized at one parameter vector
(:class:`Linearization`).

Notes
-----
Measured outputs z_k at operating points u_k, model outputs y_k(p), output noise
v_k ~ N(0, R) with R diagonal per channel and point. The ML cost (known R) is

.. math::  J(p) = ½ Σ_k r_kᵀ R⁻¹ r_k,\qquad r_k = z_k − y_k(p),

i.e. half the sum of squared *whitened* residuals r̃ = R^(−½) r. The parameters are
moved in a subspace of the scaled parameters p̃ = (p − p₀)/scale:

.. math::  p = p₀ + D B θ,

with B = I (full nodal ML), B = V_ID (the retained right singular vectors, the
truncated-SVD estimator of Bottasso et al. 2014) or B = L with P = L Lᵀ (the MAP's
prior-whitened coordinates). The estimators are in :mod:`calib.calibration.gauss_newton`.

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from calib.calibration.identifiability import whitened_sensitivities
from calib.types import Evaluation, OperatingConditions


def _read_only(values, dtype) -> np.ndarray:
    """A read-only copy of ``values`` as a 1-D array of ``dtype``."""
    out = np.array(values, dtype=dtype).reshape(-1)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class ProblemStatement:
    """One calibration problem's statement: what is estimated, from where, within which bounds,
    under which prior, from which model channels. Built once
    (:class:`calib.calibration.calibrator.Calibrator`) and read by the estimators
    (:class:`LeastSquaresProblem`), the uncertainty terms
    (:class:`calib.calibration.uncertainty_terms.ModelTerms`) and the result's estimate; nothing
    else holds a copy. Frozen, its arrays read-only.

    Parameters
    ----------
    parameters : tuple of Parameter
        The model's parameters, n_params of them.
    p0 : ndarray, shape (n_params,)
        Nominal values, the reference of the scaled coordinates p̃ = (p − p₀)/scale and of the
        prior [parameter units].
    scale : ndarray, shape (n_params,)
        Scales, > 0 [parameter units].
    lower, upper : ndarray, shape (n_params,)
        Effective bounds: the parameters' own, with the correction field's lower bounds (e.g.
        C_D >= C_D,min at the nodes) applied [parameter units].
    prior_std : ndarray, shape (n_params,)
        Prior 1-σ [parameter units]: stated in the settings, the parameter's own, or the settings'
        ``prior_sigma`` × scale.
    prior_stated : ndarray of bool, shape (n_params,)
        Whether someone stated the prior (the settings, the parameter, or the correction field's
        smooth-field prior at its nodes); the MAP estimator is flat where not.
    channel_index : tuple of int
        The column of each measured channel in the model's output, n_channels of them.
    """

    parameters: tuple
    p0: np.ndarray
    scale: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    prior_std: np.ndarray
    prior_stated: np.ndarray
    channel_index: tuple

    def __post_init__(self):
        object.__setattr__(self, "parameters", tuple(self.parameters))
        object.__setattr__(self, "channel_index", tuple(int(i) for i in self.channel_index))
        for f in fields(self):
            if f.name not in ("parameters", "channel_index"):
                value = _read_only(getattr(self, f.name), bool if f.name == "prior_stated" else float)
                object.__setattr__(self, f.name, value)
                if value.shape != self.p0.shape:
                    raise ValueError(f"ProblemStatement.{f.name} has {value.size} values, p0 {self.p0.size}")
        if len(self.parameters) != self.p0.size:
            raise ValueError(f"ProblemStatement has {len(self.parameters)} parameters, p0 {self.p0.size} values")


@dataclass(eq=False)
class Linearization:
    """Model outputs and whitened sensitivities at one parameter vector.

    Attributes
    ----------
    p : ndarray, shape (n_params,)
    residual : ndarray, shape (n_points, n_channels)
        Whitened residuals (z − y)/σ [-]; 0 at failed points.
    ok : ndarray of bool, shape (n_points,)
        Converged points.
    M : ndarray, shape (n_points * n_channels, n_params) or None
        Whitened scaled sensitivities ∂y/∂p̃ / σ (zero rows at failed points).
    evaluation : Evaluation
    """

    p: np.ndarray
    residual: np.ndarray
    ok: np.ndarray
    M: np.ndarray | None
    evaluation: Evaluation

    @property
    def cost(self) -> float:
        """½ Σ r̃² over converged points."""
        return 0.5 * float(np.sum(self.residual[self.ok] ** 2))

    @property
    def n_failed(self) -> int:
        return int(np.count_nonzero(~self.ok))


class LeastSquaresProblem:
    """The weighted least-squares (ML, known R) problem on a ForwardModel.

    Parameters
    ----------
    model : ForwardModel
    conditions : OperatingConditions
        n_points operating conditions.
    measured : ndarray, shape (n_points, n_channels)
        Measured outputs z [channel units].
    sigma : ndarray, shape (n_points, n_channels)
        1-σ noise [channel units].
    statement : ProblemStatement
        The nominal values, scales, effective bounds and channel columns (read from it, not copied).
    """

    def __init__(self, model, conditions: OperatingConditions, measured: np.ndarray, sigma: np.ndarray,
                 statement: ProblemStatement):
        self.model = model
        self.conditions = conditions
        self.measured = np.asarray(measured, float)
        self.sigma = np.asarray(sigma, float)
        self.statement = statement
        self.n_evaluations = 0
        self.n_jacobians = 0
        self.n_failed_points_total = 0
        self._cache: Linearization | None = None

    def with_sigma(self, sigma: np.ndarray) -> "LeastSquaresProblem":
        """The same problem with another noise level (the cache is dropped)."""
        new = LeastSquaresProblem(self.model, self.conditions, self.measured, sigma, self.statement)
        new.n_evaluations, new.n_jacobians = self.n_evaluations, self.n_jacobians
        new.n_failed_points_total = self.n_failed_points_total
        return new

    def p_of(self, basis: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """p = p₀ + D B θ."""
        st = self.statement
        return st.p0 + st.scale * (basis @ theta)

    def scaled(self, p: np.ndarray) -> np.ndarray:
        """p̃ = (p − p₀)/scale."""
        return (np.asarray(p, float) - self.statement.p0) / self.statement.scale

    def unscaled(self, x: np.ndarray, clip: bool = False) -> np.ndarray:
        """p = p₀ + scale · x (the inverse of :meth:`scaled`), held inside the bounds when ``clip``."""
        st = self.statement
        p = st.p0 + st.scale * np.asarray(x, float)
        return np.clip(p, st.lower, st.upper) if clip else p

    def _residual(self, ev: Evaluation):
        y = ev.values[:, self.statement.channel_index]
        ok = ev.ok & np.all(np.isfinite(y), axis=1)
        r = np.where(ok[:, None], (self.measured - np.where(ok[:, None], y, 0.0)) / self.sigma, 0.0)
        self.n_failed_points_total += int(np.count_nonzero(~ok))
        return r, ok

    def remember(self, lin: Linearization) -> None:
        """Make ``lin``, a linearization of this problem computed earlier, the cached one, so that
        going back to its point costs no model call (the cache holds one point)."""
        if lin.M is None:
            raise ValueError("remember() takes a linearization with sensitivities")
        self._cache = lin

    def evaluate(self, p: np.ndarray) -> Linearization:
        """Outputs and residuals at ``p`` (no sensitivities)."""
        p = np.asarray(p, float)
        if self._cache is not None and np.array_equal(self._cache.p, p):
            return self._cache
        ev = self.model.evaluate(p, self.conditions)
        self.n_evaluations += 1
        r, ok = self._residual(ev)
        return Linearization(p.copy(), r, ok, None, ev)

    def linearize(self, p: np.ndarray) -> Linearization:
        """Outputs, residuals and whitened scaled sensitivities at ``p`` (cached)."""
        p = np.asarray(p, float)
        if self._cache is not None and self._cache.M is not None and np.array_equal(self._cache.p, p):
            return self._cache
        ev, G = self.model.jacobian(p, self.conditions)
        self.n_jacobians += 1
        r, ok = self._residual(ev)
        M = self._whitened_sensitivities(G, ok)
        self._cache = Linearization(p.copy(), r, ok, M, ev)
        return self._cache

    def _whitened_sensitivities(self, G: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """The whitening hook of :meth:`linearize`: R^(−½) ∂y/∂p̃ of the measured channels, shape
        (n_points * n_channels, n_params), zero rows at failed points (``G`` the model's full
        Jacobian, shape (n_points, n_outputs, n_params)). A problem with another noise covariance
        (:class:`calib.calibration.errors_in_variables.MarginalProblem`) overrides it."""
        return whitened_sensitivities(G[:, self.statement.channel_index, :], self.sigma, self.statement.scale, ok)
