"""The bound-constrained quadratic programs of the Gauss–Newton iteration
(:mod:`calib.calibration.gauss_newton`), by name (:data:`OPTIMIZERS`): CasADi ``nlpsol`` with
``sqpmethod`` (the SQP of the method) or ``ipopt``, or SciPy ``slsqp`` / ``trust-constr``.

References
----------
J. Nocedal, S.J. Wright, Numerical Optimization, 2nd ed., Springer (2006), ch. 16, 18.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from calib.errors import InputError


@dataclass
class QpSolution:
    """A QP solver's answer.

    Attributes
    ----------
    x : ndarray, shape (n_theta,)
        The step [scale units].
    success : bool
        The solver reports success and the step is finite.
    message : str
        The solver's own status text.
    """

    x: np.ndarray
    success: bool
    message: str


class CasadiQp:
    """Bound-constrained QP through CasADi ``nlpsol`` (``sqpmethod`` or ``ipopt``).

    The QP data (H, g, A) enter as NLP parameters, so one solver instance per problem
    size is built and reused.
    """

    def __init__(self, plugin: str):
        self.plugin = plugin
        self._solvers: dict = {}

    def _solver(self, n: int, m: int):
        key = (n, m)
        if key not in self._solvers:
            import casadi as ca

            x = ca.SX.sym("x", n)
            H = ca.SX.sym("H", n, n)
            g = ca.SX.sym("g", n)
            A = ca.SX.sym("A", m, n)
            f = 0.5 * ca.dot(x, ca.mtimes(H, x)) + ca.dot(g, x)
            nlp = {"x": x, "p": ca.vertcat(ca.vec(H), g, ca.vec(A)), "f": f, "g": ca.mtimes(A, x)}
            if self.plugin == "ipopt":
                opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
                        "ipopt.tol": 1e-10, "ipopt.max_iter": 200, "error_on_fail": False}
            else:
                opts = {"qpsol": "qrqp", "print_time": False, "print_header": False,
                        "print_iteration": False, "print_status": False, "max_iter": 50,
                        "error_on_fail": False,
                        "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False,
                                          "error_on_fail": False}}
            self._solvers[key] = ca.nlpsol(f"qp_{self.plugin}_{n}_{m}", self.plugin, nlp, opts)
        return self._solvers[key]

    def __call__(self, H, g, A, lb, ub) -> QpSolution:
        n, m = H.shape[0], A.shape[0]
        solver = self._solver(n, m)
        par = np.concatenate([H.reshape(-1, order="F"), g, A.reshape(-1, order="F")])
        sol = solver(x0=np.zeros(n), p=par, lbg=lb, ubg=ub)
        stats = solver.stats()
        x = np.asarray(sol["x"]).reshape(-1)
        status = str(stats.get("return_status", ""))
        ok = bool(stats.get("success", False))
        if not ok and status == "Search_Direction_Becomes_Too_Small":
            # the QP is strictly convex and sqpmethod's first iterate is its exact solution (exact
            # Hessian, qrqp); a vanishing search direction after it means the iterate cannot be
            # improved, which sqpmethod reports as a failure when its KKT test misses by scaling.
            # Accept it if it does not do worse than the start x = 0
            ok = bool(0.5 * x @ H @ x + g @ x <= 1e-12 * (1.0 + float(np.abs(g) @ np.abs(x))))
        return QpSolution(x, ok and bool(np.all(np.isfinite(x))), status)


class ScipyQp:
    """Bound-constrained QP through ``scipy.optimize.minimize`` (SLSQP or trust-constr)."""

    def __init__(self, method: str):
        self.method = method

    def __call__(self, H, g, A, lb, ub) -> QpSolution:
        from scipy.optimize import LinearConstraint, minimize

        n = H.shape[0]
        # SLSQP's tolerances are absolute: solve in variables w with x = √gain D⁻¹ w, D = √diag(H),
        # and cost divided by gain = ½ gᵀH⁺g (the unconstrained Newton decrease), so that the
        # Hessian has a unit diagonal and the optimal w and cost are of order one
        newton = np.linalg.lstsq(H, g, rcond=None)[0]
        gain = 0.5 * float(g @ newton)
        if not gain > 1e-14:  # even the unconstrained step gains nothing: x = 0 is optimal
            return QpSolution(np.zeros(n), True, "already optimal (no decrease available)")
        d = np.sqrt(np.maximum(np.diag(H), 1e-300))
        x_of = np.sqrt(gain) / d
        H = H * np.outer(x_of, x_of) / gain
        g = g * x_of / gain
        A = A * x_of[None, :]
        fun = lambda x: 0.5 * x @ H @ x + g @ x  # noqa: E731
        jac = lambda x: H @ x + g  # noqa: E731
        if self.method == "SLSQP":
            cons = []
            lo, hi = np.isfinite(lb), np.isfinite(ub)
            if lo.any():
                cons.append({"type": "ineq", "fun": lambda x: A[lo] @ x - lb[lo], "jac": lambda x: A[lo]})
            if hi.any():
                cons.append({"type": "ineq", "fun": lambda x: ub[hi] - A[hi] @ x, "jac": lambda x: -A[hi]})
            res = minimize(fun, np.zeros(n), jac=jac, method="SLSQP", constraints=cons,
                           options={"maxiter": 500, "ftol": 1e-12})
        else:
            res = minimize(fun, np.zeros(n), jac=jac, hess=lambda x: H, method="trust-constr",
                           constraints=[LinearConstraint(A, lb, ub)],
                           options={"maxiter": 1000, "gtol": 1e-10, "xtol": 1e-12})
        x = np.asarray(res.x, float) * x_of
        return QpSolution(x, bool(res.success) and np.all(np.isfinite(x)), str(res.message))


#: Optimizers by name (the QP subproblem solver of the Gauss–Newton iteration).
OPTIMIZERS: dict[str, Callable] = {
    "sqpmethod": lambda: CasadiQp("sqpmethod"),
    "ipopt": lambda: CasadiQp("ipopt"),
    "slsqp": lambda: ScipyQp("SLSQP"),
    "trust-constr": lambda: ScipyQp("trust-constr"),
}
_INSTANCES: dict = {}


def get_optimizer(name: str):
    """The optimizer registered as ``name``; the error lists the valid names.

    One instance per name and process: a CasADi solver builds (and compiles) one NLP per problem
    size, which every later estimation of that size reuses.
    """
    if name not in OPTIMIZERS:
        raise InputError(f"unknown optimizer {name!r}; valid optimizers: {', '.join(OPTIMIZERS)}",
                         "estimation", field="optimizer")
    if name not in _INSTANCES:
        _INSTANCES[name] = OPTIMIZERS[name]()
    return _INSTANCES[name]
