r"""Errors in variables: operating conditions measured with an uncertainty (the *marginal* estimator;
the *joint* one, which shares its sensitivities and factors, and the choice between them in
:mod:`calib.calibration.eiv_joint`).

Each point's measured conditions u_k = (V, Ω, β, ρ)_k (wind speed [m/s], rotor speed [rpm], pitch
[deg], air density [kg/m³]) differ from the true ones by a zero-mean error with covariance Σ_u,k (diagonal: the
conditions' 1-σ, :func:`condition_sigma`). To first order the model output at the true conditions is
y(p, u_k) − J_u,k e_k, so the measured outputs z_k scatter about y(p, u_k) with the *effective*
covariance

.. math::  C_k = R_k + J_{u,k} Σ_{u,k} J_{u,k}ᵀ,

R_k = diag(σ_k²) the output noise and J_u,k = ∂y_k/∂u_k (n_channels × 4) the output sensitivities
to the point's conditions. C_k is a full block per point (the channels of one point share the
condition error) and block-diagonal over points. The marginal estimator whitens the residuals
and sensitivities of each point with the Cholesky factor C_k = L_k L_kᵀ,

.. math::  r̃_k = L_k⁻¹ (z_k − y_k(p)),\qquad M_k = L_k⁻¹ G_k D,

and runs the calibrator's estimator (MAP or truncated ML) on that problem; J_u is re-linearized
at the estimate and the fit repeated until the estimate's move changes the whitened fit by less than
``EIV_SETTLED`` standard deviations, at most ``max_eiv_iterations`` fits (the iteratively re-weighted form of the
effective-variance method: C_k is held fixed within a fit, so the ½ log det C_k term and the
dependence of C_k on p do not enter the gradient).

J_u is computed by central differences through the model's ``evaluate`` (two batch evaluations per
uncertain condition): the ForwardModel contract exposes derivatives with respect to the parameters
only, not to the conditions.

References
----------
J. Orear, Least squares when both variables have uncertainties, Am. J. Phys. 50 (1982) 912-916
(the effective variance).
C. Wang, F. Campagnolo, C.L. Bottasso, Identification of airfoil polars from uncertain
experimental measurements, Wind Energ. Sci. 5 (2020) 1537-1550 (errors in variables for the
calibration of lifting-line polars).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib.calibration.problem import LeastSquaresProblem
from calib.calibration.settings import UNCERTAIN_CONDITIONS
from calib.errors import InputError
from calib.types import OperatingConditions


#: Units of the conditions' σ (those of the conditions, :class:`calib.types.OperatingConditions`).
CONDITION_UNITS = {"wind_speed": "m/s", "rotor_speed": "rpm", "pitch": "deg", "air_density": "kg/m^3"}

#: Length of the last fit's move ‖M (p̃_k+1 − p̃_k)‖ (the change of the whitened fitted outputs, in
#: standard deviations of the data) below which the re-linearization of J_u has settled [-]: a
#: move of a tenth of a standard deviation along the best-determined direction, far less along
#: the others. (In parameter scales the poorly determined directions, held by their prior, keep
#: moving by a few hundredths per fit on the validation's campaigns.)
EIV_SETTLED = 0.1

#: Central-difference steps of J_u: relative to the condition's value (wind and rotor speed) and
#: absolute (pitch [deg]); the air density's relative. Small against the conditions' σ (3 % and 0.2 deg
#: in the field, about 0.3 % for the density from temperature and pressure), large
#: against the BEM's convergence tolerance.
STEP_RELATIVE = 1e-4
STEP_PITCH_DEG = 1e-3



def condition_sigma(m, settings) -> np.ndarray | None:
    """1-σ of every point's conditions [condition units], or None when none is stated or all are zero.

    The table's ``wind_speed_sigma``, ``rotor_speed_sigma``, ``pitch_sigma`` and ``air_density_sigma``
    columns (the last, where the density comes from a temperature and a pressure, e.g. from
    :func:`calib.scada.density.air_density_sigma`)
    (:attr:`calib.measurements.Measurements.condition_sigma`), the settings' absolute
    ``condition_sigma`` and relative ``condition_relative_sigma`` (a fraction of each point's
    value) add in quadrature: σ² = σ_table² + σ_abs² + (r |u|)².

    Parameters
    ----------
    m : Measurements
    settings : CalibrationSettings

    Returns
    -------
    ndarray, shape (n_points, 4) or None
        Columns :data:`UNCERTAIN_CONDITIONS` [m/s, rpm, deg, kg/m³].
    """
    n = m.n_points
    var = np.zeros((n, len(UNCERTAIN_CONDITIONS)))
    table = m.condition_sigma or {}
    absolute = settings.condition_sigma or {}
    relative = settings.condition_relative_sigma or {}
    for j, name in enumerate(UNCERTAIN_CONDITIONS):
        if name in table:
            var[:, j] += np.asarray(table[name], float) ** 2
        var[:, j] += float(absolute.get(name, 0.0)) ** 2
        var[:, j] += (float(relative.get(name, 0.0)) * np.abs(getattr(m.conditions, name))) ** 2
    if not np.any(var > 0):
        return None
    return np.sqrt(var)


def check_noise_mode(settings, source: str = "settings") -> None:
    """Refuse a noise model the marginal estimator does not support.

    The effective covariance needs the output noise R stated (``known``, ``relative`` or
    ``repeats``): with ``ml`` or ``relative_ml`` the residuals' scatter would carry the
    conditions' share twice (once in R estimated from it, once in J_u Σ_u J_uᵀ).

    Raises
    ------
    InputError
        ``noise`` is ``ml`` or ``relative_ml`` while condition σ are stated.
    """
    if settings.noise in ("ml", "relative_ml"):
        raise InputError(f"noise = \"{settings.noise}\" estimates the output noise from the residuals, which "
                         "already hold the scatter of the conditions: with condition σ (wind_speed_sigma, "
                         "rotor_speed_sigma, pitch_sigma or [calibration] condition_sigma) state the output "
                         "noise (noise = \"known\" with sigma or _sigma columns, \"relative\" with relative_sigma, "
                         "or \"repeats\"), or set errors_in_variables = \"ignore\"", source,
                         field="calibration.noise")


def uncertain_conditions(m, settings) -> np.ndarray | None:
    """The conditions' σ the calibration takes into its fit (:func:`condition_sigma`), or None: none
    stated, all zero, or ``errors_in_variables = "ignore"``.

    Raises
    ------
    InputError
        Condition σ stated with a noise model the marginal estimator does not support
        (:func:`check_noise_mode`).
    """
    if settings.errors_in_variables not in ("marginal", "joint"):
        return None
    sigma_u = condition_sigma(m, settings)
    if sigma_u is not None:
        check_noise_mode(settings, m.source)
    return sigma_u


def condition_sensitivities(model, p: np.ndarray, conditions: OperatingConditions, channel_index,
                            sigma_u: np.ndarray) -> tuple[np.ndarray, int]:
    """∂y/∂u of every point's measured channels by central differences through ``model.evaluate``.

    Parameters
    ----------
    model : ForwardModel
    p : ndarray, shape (n_params,)
    conditions : OperatingConditions
        n_points conditions (as measured).
    channel_index : sequence of int
        The measured channels' columns in the model's output.
    sigma_u : ndarray, shape (n_points, 4)
        Conditions' σ (columns :data:`UNCERTAIN_CONDITIONS`); a condition with σ = 0 at every
        point is not differenced.

    Returns
    -------
    J_u : ndarray, shape (n_points, n_channels, 4)
        [channel unit per m/s, rpm, deg, kg/m³]; zero for a condition without σ and at points where a
        difference failed.
    n_failed : int
        Points where a difference evaluation failed (their J_u row for that condition is zero).
    """
    idx = list(channel_index)
    n = len(conditions)
    J = np.zeros((n, len(idx), len(UNCERTAIN_CONDITIONS)))
    failed = np.zeros(n, bool)
    for j, name in enumerate(UNCERTAIN_CONDITIONS):
        if not np.any(sigma_u[:, j] > 0):
            continue
        u = getattr(conditions, name)
        h = np.full(n, STEP_PITCH_DEG) if name == "pitch" else STEP_RELATIVE * np.maximum(np.abs(u), 1.0)
        plus = model.evaluate(p, replace(conditions, **{name: u + h}))
        minus = model.evaluate(p, replace(conditions, **{name: u - h}))
        yp, ym = plus.values[:, idx], minus.values[:, idx]
        ok = plus.ok & minus.ok & np.all(np.isfinite(yp), axis=1) & np.all(np.isfinite(ym), axis=1)
        J[:, :, j] = np.where(ok[:, None], (yp - ym) / (2.0 * h[:, None]), 0.0)
        failed |= ~ok & (sigma_u[:, j] > 0)
    return J, int(np.count_nonzero(failed))


def effective_cholesky(sigma_y: np.ndarray, J_u: np.ndarray, sigma_u: np.ndarray) -> np.ndarray:
    """Lower Cholesky factors of C_k = diag(σ_y,k²) + J_u,k diag(σ_u,k²) J_u,kᵀ per point.

    Parameters
    ----------
    sigma_y : ndarray, shape (n_points, n_channels)
        Output 1-σ [channel units], > 0.
    J_u : ndarray, shape (n_points, n_channels, 4)
    sigma_u : ndarray, shape (n_points, 4)

    Returns
    -------
    ndarray, shape (n_points, n_channels, n_channels)
    """
    A = J_u * sigma_u[:, None, :]
    C = np.einsum("kcu,kdu->kcd", A, A)
    n_ch = sigma_y.shape[1]
    C[:, np.arange(n_ch), np.arange(n_ch)] += sigma_y ** 2
    return np.linalg.cholesky(C)


class MarginalProblem(LeastSquaresProblem):
    """The least-squares problem whitened by each point's effective covariance (module docstring).

    Parameters
    ----------
    model, conditions, measured, statement
        As :class:`calib.calibration.problem.LeastSquaresProblem`.
    sigma_y : ndarray, shape (n_points, n_channels)
        Output 1-σ [channel units].
    chol : ndarray, shape (n_points, n_channels, n_channels)
        Lower Cholesky factors of the effective covariances (:func:`effective_cholesky`).

    Notes
    -----
    ``sigma`` (read by the result's per-channel χ², residual tables and the prior check) is the
    square root of C_k's diagonal: the effective σ of each value, without the correlation of
    the channels of one point, which the estimator's residuals and sensitivities carry.
    """

    def __init__(self, model, conditions: OperatingConditions, measured: np.ndarray, sigma_y: np.ndarray,
                 statement, chol: np.ndarray):
        diag = np.sqrt(np.einsum("kcd,kcd->kc", chol, chol))
        super().__init__(model, conditions, measured, diag, statement)
        self.sigma_y = np.asarray(sigma_y, float)
        self.chol = chol

    def with_sigma(self, sigma: np.ndarray) -> "LeastSquaresProblem":
        raise NotImplementedError("the marginal problem's noise is stated (check_noise_mode)")

    def _whiten(self, a: np.ndarray) -> np.ndarray:
        """L_k⁻¹ a_k per point; ``a`` of shape (n_points, n_channels) or (n_points, n_channels, m)."""
        if a.ndim == 2:
            return np.linalg.solve(self.chol, a[..., None])[..., 0]
        return np.linalg.solve(self.chol, a)

    def _residual(self, ev):
        y = ev.values[:, self.statement.channel_index]
        ok = ev.ok & np.all(np.isfinite(y), axis=1)
        d = np.where(ok[:, None], self.measured - np.where(ok[:, None], y, 0.0), 0.0)
        r = np.where(ok[:, None], self._whiten(d), 0.0)
        self.n_failed_points_total += int(np.count_nonzero(~ok))
        return r, ok

    def _whitened_sensitivities(self, G: np.ndarray, ok: np.ndarray) -> np.ndarray:
        """L_k⁻¹ ∂y_k/∂p̃ per point (the whitening hook of :meth:`LeastSquaresProblem.linearize`)."""
        Gs = np.nan_to_num(G[:, self.statement.channel_index, :] * self.statement.scale[None, None, :],
                           nan=0.0, posinf=0.0, neginf=0.0)
        return np.where(ok[:, None, None], self._whiten(Gs), 0.0).reshape(-1, G.shape[-1])


def marginal_problem(model, m, sigma_y: np.ndarray, sigma_u: np.ndarray, statement, p: np.ndarray,
                     base: LeastSquaresProblem | None = None) -> tuple[MarginalProblem, int]:
    """The marginal problem with J_u linearized at ``p`` (and the count of failed differences).

    ``base``'s model-call counters are carried over when given.
    """
    J_u, n_failed = condition_sensitivities(model, p, m.conditions, statement.channel_index, sigma_u)
    chol = effective_cholesky(sigma_y, J_u, sigma_u)
    problem = MarginalProblem(model, m.conditions, m.values, sigma_y, statement, chol)
    if base is not None:
        problem.n_evaluations = base.n_evaluations + 2 * int(np.count_nonzero(np.any(sigma_u > 0, axis=0)))
        problem.n_jacobians = base.n_jacobians
        problem.n_failed_points_total = base.n_failed_points_total
    return problem, n_failed


def fit_marginal(cal, problem: LeastSquaresProblem, sigma_u: np.ndarray, p: np.ndarray):
    """The marginal estimator's outer loop: J_u at the estimate, a fit, until the estimate settles.

    Parameters
    ----------
    cal : Calibrator
        Its fitter (MAP or truncated), statement, measurements, settings and progress records.
    problem : LeastSquaresProblem
        The output-error problem with the stated output σ.
    sigma_u : ndarray, shape (n_points, 4)
        The conditions' 1-σ (:func:`condition_sigma`).
    p : ndarray, shape (n_params,)
        Start [parameter units].

    Returns
    -------
    problem : MarginalProblem
        The problem at the last J_u.
    fit : FitOutcome
    message : str
        The fit's message with the outer iterations' count and whether they settled.
    """
    st = cal.settings
    statement = cal.statement
    change = np.inf
    n_failed_total = 0
    for k in range(st.max_eiv_iterations):
        problem, n_failed = marginal_problem(cal.model, cal.measurements, problem.sigma if k == 0 else problem.sigma_y,
                                             sigma_u, statement, p, base=problem)
        n_failed_total = max(n_failed_total, n_failed)
        fit = cal.fitter.fit(problem, p)
        change = float(np.linalg.norm(fit.lin.M @ ((fit.p - p) / statement.scale))) if fit.lin.M is not None \
            else float(np.max(np.abs((fit.p - p) / statement.scale)))
        p = fit.p
        cal.emit({"stage": "errors_in_variables", "iteration": k + 1, "change": change,
                  "n_failed_differences": n_failed, "status": fit.status})
        if change < EIV_SETTLED:
            break
    settled = change < EIV_SETTLED
    # the result is assembled with the last fit's J_u, linearized at the estimate before it (settled: moved < EIV_SETTLED since)
    text = (f"errors in variables (marginal): {k + 1} fit(s) re-linearizing the conditions' sensitivities, "
            + (f"settled (last move {change:.2g} < {EIV_SETTLED:g} σ of the data)" if settled else
               f"NOT settled after max_eiv_iterations = {st.max_eiv_iterations} (last move {change:.2g} σ of "
               f"the data, settled below {EIV_SETTLED:g})"))
    if n_failed_total:
        text += f"; the conditions' sensitivities failed at {n_failed_total} point(s) (condition scatter left out there)"
    message = f"{fit.message}; {text}" if fit.message else text
    return problem, fit, message
