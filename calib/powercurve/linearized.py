"""The linearized (delta-method) uncertainty of a scheduled power curve: :func:`delta_method`."""

from __future__ import annotations

import numpy as np

from calib.powercurve.schedule import TSR_GRID, ScheduledCurve
from calib.types import OperatingConditions

__all__ = ["delta_method"]


def delta_method(model, p_hat, cov, central: ScheduledCurve, air_density: float, schedule=None):
    """Linearized 1-σ of power, thrust and pitch per bin, through the schedule at the central curve.

    Region 2 and fixed schedules: σ² = g Cov gᵀ with g the exact row of the model Jacobian at the
    central operating point. When the schedule re-finds the optimal λ per parameter vector
    (``VariableSpeed(tsr_rule="optimal")``), the bins whose rotor speed is not at a limit also move
    with λ*(p): g += ∂P/∂Ω · (∂Ω/∂λ) · dλ*/dp, with dλ*/dp the derivative of the schedule's own λ*, the
    vertex of its parabola through three grid points (:func:`_vertex_gradient`, the exact Jacobian of C_P
    there; ∂P/∂Ω by a 0.01 rpm forward difference). Region 3: the pitch holds rated power, σ_P = 0,
    dβ/dp = −(∂P/∂p)/(∂P/∂β), and the thrust moves by ∂T/∂p + ∂T/∂β dβ/dp (∂/∂β by a 0.01° forward
    difference).

    Returns
    -------
    std : dict of str to ndarray, shape (n_bins,)
        ``power`` [W], ``thrust`` [N], ``pitch`` [deg]; NaN where the central bin failed.
    grad_power : ndarray, shape (n_bins, n_params)
        dP_i/dp of the scheduled power [W per parameter unit] (zero rows in region 3).
    pitch_grad : ndarray, shape (n_bins, n_params)
        dβ_i/dp [deg per parameter unit] (zero rows outside region 3).
    dpower_dpitch : ndarray, shape (n_bins,)
        ∂P/∂β at the central point [W/deg] in region 3, NaN elsewhere.
    """
    v, rpm, beta = central.wind_speed, central.rotor_speed, central.pitch
    cond = OperatingConditions(v, rpm, beta, air_density)
    ev, G = model.jacobian(p_hat, cond)
    names = [c.name for c in model.channels]
    gP, gT = G[:, names.index("power"), :].copy(), G[:, names.index("thrust"), :].copy()
    solve = lambda k, w, b: model.solve(p_hat, OperatingConditions(v[k], w, b, air_density))  # noqa: E731
    if getattr(schedule, "tsr_rule", None) == "optimal" and np.isfinite(central.tsr_opt):
        k = np.flatnonzero((central.region == 2) & (rpm > schedule.min_rotor_speed + 1e-9)
                           & (rpm < schedule.max_rotor_speed - 1e-9))
        dlam_dp = _vertex_gradient(model, p_hat, schedule, air_density, names.index("power"))
        if k.size and np.any(dlam_dp):
            r0, r1 = solve(k, rpm[k], beta[k]), solve(k, rpm[k] + 0.01, beta[k])
            drpm_dlam = v[k] / schedule.rotor_radius * 30 / np.pi
            gP[k] += ((r1.power - r0.power) / 0.01 * drpm_dlam)[:, None] * dlam_dp
            gT[k] += ((r1.thrust - r0.thrust) / 0.01 * drpm_dlam)[:, None] * dlam_dp
    r3 = central.region == 3
    g_pitch = np.zeros_like(gP)
    dP_dpitch = np.full(v.size, np.nan)
    if np.any(r3):
        k = np.flatnonzero(r3)
        r0, r1 = solve(k, rpm[k], beta[k]), solve(k, rpm[k], beta[k] + 0.01)
        dP_db, dT_db = (r1.power - r0.power) / 0.01, (r1.thrust - r0.thrust) / 0.01
        g_pitch[k] = -gP[k] / dP_db[:, None]
        dP_dpitch[k] = dP_db
        gT[k] = gT[k] + dT_db[:, None] * g_pitch[k]
        gP[k] = 0.0
    var = lambda g: np.einsum("ij,jk,ik->i", np.nan_to_num(g), cov, np.nan_to_num(g))  # noqa: E731
    bad = ~central.ok | ~ev.ok
    std = {name: np.where(bad, np.nan, np.sqrt(np.maximum(var(g), 0.0)))
           for name, g in (("power", gP), ("thrust", gT), ("pitch", g_pitch))}
    return std, np.where(bad[:, None], np.nan, gP), np.nan_to_num(g_pitch), dP_dpitch


def _vertex_gradient(model, p_hat, schedule, air_density: float, i_power: int) -> np.ndarray:
    """dλ*/dp of the schedule's optimal λ as :meth:`~calib.powercurve.schedule.VariableSpeed.optimal_tsr` finds
    it [1 per parameter unit]: the vertex of the parabola through the best grid point and its neighbours,
    λ* = λ_k + h (y₋ − y₊) / (2 (y₋ − 2y₀ + y₊)) (y the C_P at λ_k − h, λ_k, λ_k + h), differentiated with the
    exact Jacobian of C_P at those three points (the grid and the best point held). Zero where the schedule
    takes the grid point itself (the best point at the grid's edge, a parabola not concave, or its vertex
    clipped to the three points). The derivative of the implemented λ*, not of the continuous maximum: where
    the calibrated C_P(λ) has kinks (a correction field's nodes), −(∂²C_P/∂λ∂p)/(∂²C_P/∂λ²) at λ* can be
    far from how the schedule's λ* moves."""
    lam = schedule.design_tsr * TSR_GRID
    omega = schedule.max_rotor_speed * np.pi / 30
    vl = omega * schedule.rotor_radius / lam
    cond = lambda i: OperatingConditions(vl[i], np.full(i.size, schedule.max_rotor_speed),  # noqa: E731
                                         np.full(i.size, schedule.fine_pitch), air_density)
    q = 0.5 * air_density * np.pi * schedule.rotor_radius ** 2 * vl ** 3
    res = model.solve(p_hat, cond(np.arange(lam.size)))          # values on the grid, the Jacobian at three
    cp = np.where(res.ok, res.power / q, -np.inf)
    k = int(np.argmax(cp))
    zero = np.zeros(np.asarray(p_hat).size)
    if not 0 < k < lam.size - 1 or not np.all(np.isfinite(cp[k - 1:k + 2])):
        return zero
    three = np.arange(k - 1, k + 2)
    ev, G = model.jacobian(p_hat, cond(three))
    if not np.all(ev.ok):
        return zero
    y = ev.values[:, i_power] / q[three]
    g = G[:, i_power, :] / q[three, None]
    h = lam[k + 1] - lam[k]
    d = y[0] - 2 * y[1] + y[2]
    if d >= 0:
        return zero
    t = h * (y[0] - y[2]) / (2 * d)
    if abs(t) >= h:
        return zero
    return h / 2 * ((g[0] - g[2]) * d - (y[0] - y[2]) * (g[0] - 2 * g[1] + g[2])) / d ** 2
