"""The linearized (delta-method) uncertainty of a scheduled power curve: :func:`delta_method`."""

from __future__ import annotations

import numpy as np

from calib.powercurve.schedule import ScheduledCurve
from calib.types import OperatingConditions

__all__ = ["delta_method"]


def delta_method(model, p_hat, cov, central: ScheduledCurve, air_density: float, schedule=None):
    """Linearized 1-σ of power, thrust and pitch per bin, through the schedule at the central curve.

    Region 2 and fixed schedules: σ² = g Cov gᵀ with g the exact row of the model Jacobian at the
    central operating point. When the schedule re-finds the optimal λ per parameter vector
    (``VariableSpeed(tsr_rule="optimal")``), the bins whose rotor speed is not at a limit also move
    with λ*(p): g += ∂P/∂Ω · (∂Ω/∂λ) · dλ*/dp, with dλ*/dp = −(∂²C_P/∂λ∂p)/(∂²C_P/∂λ²) at λ*
    (central differences of the exact Jacobian of C_P, ±0.05 in λ; ∂P/∂Ω by a 0.01 rpm forward
    difference). Region 3: the pitch holds rated power, σ_P = 0, dβ/dp = −(∂P/∂p)/(∂P/∂β), and the
    thrust moves by ∂T/∂p + ∂T/∂β dβ/dp (∂/∂β by a 0.01° forward difference).

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
        if k.size:
            h, lam = 0.05, central.tsr_opt + np.array([-0.05, 0.0, 0.05])
            omega = schedule.max_rotor_speed * np.pi / 30
            vl = omega * schedule.rotor_radius / lam
            evl, Gl = model.jacobian(p_hat, OperatingConditions(vl, np.full(3, schedule.max_rotor_speed),
                                                                np.full(3, schedule.fine_pitch), air_density))
            q = 0.5 * air_density * np.pi * schedule.rotor_radius ** 2 * vl ** 3
            cp, gcp = evl.values[:, names.index("power")] / q, Gl[:, names.index("power"), :] / q[:, None]
            d2 = (cp[2] - 2 * cp[1] + cp[0]) / h ** 2
            dlam_dp = -(gcp[2] - gcp[0]) / (2 * h) / d2 if d2 < 0 else np.zeros(gP.shape[1])
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
