"""The residuals' curvature that the Gauss–Newton model JᵀJ leaves out, by the structured secant
update of NL2SOL, for the MAP's damped Gauss–Newton (:mod:`calib.calibration.gauss_newton`): started once
a Gauss–Newton step overshoots (accepted at once with less than :data:`SECANT_START` of the predicted
decrease), kept while its steps are predicted well, only its positive part used (:func:`psd_part`),
so that no step is longer than Gauss–Newton's.

References
----------
J.E. Dennis, D.M. Gay, R.E. Welsch, An adaptive nonlinear least-squares algorithm, ACM Trans. Math.
Softw. 7 (1981) 348-368.
J.E. Dennis, R.B. Schnabel, Numerical Methods for Unconstrained Optimization and Nonlinear Equations,
Prentice-Hall (1983), §10.3.
"""

from __future__ import annotations

import numpy as np

from calib.calibration.problem import Linearization

#: The secant curvature is kept only after a step accepted at the first damping with at least this
#: ratio of actual to predicted decrease; else it restarts from zero [-].
SECANT_RHO = 0.25

#: A Gauss–Newton step accepted at the first damping with a ratio of actual to predicted decrease below
#: this overshot (the residuals' curvature adds to JᵀJ's): the secant curvature starts from it [-].
SECANT_START = 0.5


def secant_update(S: np.ndarray, before: Linearization, after: Linearization, basis: np.ndarray, x: np.ndarray,
                   prior_weight: float) -> np.ndarray:
    r"""The structured secant update of S ≈ Σ_i r_i ∇²r_i, the residuals' curvature the Gauss–Newton
    model JᵀJ leaves out (Dennis, Gay & Welsch 1981, NL2SOL; Dennis & Schnabel 1983, §10.3).

    After the step x from (J, r) to (J₊, r₊) the updated S₊ satisfies the secant condition
    S₊ x = y♯ = (J₊ − J)ᵀ r₊ and is the symmetric change of S least in a norm weighted by the gradient
    change y = J₊ᵀ r₊ − Jᵀ r + w x (w the prior weight):

    .. math::  S_+ = τS + \frac{z yᵀ + y zᵀ}{yᵀx} − \frac{zᵀx}{(yᵀx)^2}\, y yᵀ,
               \qquad z = y♯ − τ S x,\quad τ = \min(1, |xᵀy♯| / |xᵀSx|)

    (τ the NL2SOL sizing). Unchanged when yᵀx ≤ 0 or the points that converged differ.
    Where a noisy fit's many small residuals add curvature in the weakly determined
    directions the Gauss–Newton steps overshoot by a constant factor and converge
    linearly; on ``bench_scaling``'s 648-point case the true curvature along the steps was
    1.8-1.9 times JᵀJ's (an alternating error shrinking by 0.85 per iteration).

    Parameters
    ----------
    S : ndarray, shape (n_theta, n_theta)
    before, after : Linearization
        At θ and θ + x, with sensitivities.
    basis : ndarray, shape (n_params, n_theta)
    x : ndarray, shape (n_theta,)
        The step [scale units].
    prior_weight : float

    Returns
    -------
    ndarray, shape (n_theta, n_theta)

    References
    ----------
    J.E. Dennis, D.M. Gay, R.E. Welsch, An adaptive nonlinear least-squares algorithm,
    ACM Trans. Math. Softw. 7 (1981) 348-368.
    J.E. Dennis, R.B. Schnabel, Numerical Methods for Unconstrained Optimization and Nonlinear
    Equations, Prentice-Hall (1983), §10.3.
    """
    if before.M is None or after.M is None or not np.array_equal(before.ok, after.ok):
        return S
    J0, J1 = -(before.M @ basis), -(after.M @ basis)
    r0, r1 = before.residual.reshape(-1), after.residual.reshape(-1)
    y_sharp = (J1 - J0).T @ r1
    y = J1.T @ r1 - J0.T @ r0 + prior_weight * x
    ys = float(y @ x)
    if not ys > 0.0:
        return S
    Sx = S @ x
    xSx = float(x @ Sx)
    tau = min(1.0, abs(float(x @ y_sharp)) / abs(xSx)) if xSx != 0.0 else 1.0
    z = y_sharp - tau * Sx
    out = tau * S + (np.outer(z, y) + np.outer(y, z)) / ys - (float(z @ x) / ys ** 2) * np.outer(y, y)
    return 0.5 * (out + out.T)


def psd_part(S: np.ndarray) -> np.ndarray:
    """S with its negative eigenvalues set to zero: the secant curvature lengthens no step beyond
    Gauss–Newton's, whose JᵀJ (+ I) keeps the subproblem convex."""
    w, Q = np.linalg.eigh(S)
    return (Q * np.clip(w, 0.0, None)) @ Q.T
