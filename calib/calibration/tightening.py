"""Which measurements would tighten a parameter's σ: the linearized value of a new measurement.

A calibration's covariance C of the scaled parameters (the MAP's Laplace covariance, or the
truncated estimate's with its frozen directions) answers "how well is the pitch offset known";
an engineer then asks "what should I measure to know it better". Adding measurements y = g p̃
with noise R at new operating points or channels turns C into the linear-Gaussian update

.. math::  C' = C − C Gᵀ (R + G C Gᵀ)^{-1} G C

(the Kalman / Bayesian experimental-design update; Chaloner & Verdinelli 1995), at the cost
of one model Jacobian at the candidate points. The candidates are groups an engineer can
schedule: another pitch line over the measured tip-speed ratios, the measured pitch lines
further into stall (lower λ) or towards runaway (higher λ), and each channel the campaign did
not measure at the measured points. Their noise is the campaign's: each channel's median
relative σ (σ/|y|) where measured, else the median over the measured channels, on
max(|y|, 0.1 max|y|) as in :mod:`calib.diagnosis.separation`, plus the variance the correction field the
nodes do not carry gives those outputs (the prior's, beyond the nodes): a candidate in a region
the field is free to explain informs a nuisance only through that freedom.

References
----------
K. Chaloner, I. Verdinelli, Bayesian experimental design: a review, Statistical Science 10
(1995) 273-304.
"""

from __future__ import annotations

import numpy as np

from calib.types import CONDITION_FIELDS, OperatingConditions

#: Candidate points per group: tip-speed ratios on a line, pitch lines.
LINE_POINTS = 6
FLOOR = 0.1


def candidate_groups(conditions: OperatingConditions, radius: float, channels: list, measured: list) -> list:
    """(label, conditions, channel names) of the candidate measurement groups.

    Parameters
    ----------
    conditions : OperatingConditions
        The measured points.
    radius : float
        Rotor radius [m].
    channels : list of str
        The model's channels.
    measured : list of str
        The campaign's channels.
    """
    lam = conditions.tip_speed_ratio(radius)
    rpm = float(np.median(conditions.rotor_speed))
    rho, yaw = float(np.median(conditions.air_density)), float(np.median(conditions.yaw))
    pitches = np.unique(np.round(conditions.pitch, 6))

    def line(lams, pitch_values):
        L, P = (a.ravel() for a in np.meshgrid(lams, pitch_values, indexing="ij"))
        return OperatingConditions(rpm * np.pi / 30.0 * radius / L, np.full(L.size, rpm), P, rho, yaw)

    lams = np.linspace(lam.min(), lam.max(), LINE_POINTS)
    out = []
    step = max(2.0, float(np.median(np.diff(pitches))) if pitches.size > 1 else 2.0)
    for pitch in (pitches.min() - step, pitches.max() + step):
        out.append((f"another pitch line, {pitch:.3g} deg, at λ {lam.min():.3g}–{lam.max():.3g}",
                    line(lams, [pitch]), list(measured)))
    low = np.linspace(max(1.0, 0.5 * lam.min()), lam.min(), LINE_POINTS + 1)[:-1]
    out.append((f"the measured pitch lines further into stall, λ {low[0]:.3g}–{low[-1]:.3g}", line(low, pitches),
                list(measured)))
    high = np.linspace(lam.max(), 1.4 * lam.max(), LINE_POINTS + 1)[1:]
    out.append((f"the measured pitch lines towards runaway, λ {high[0]:.3g}–{high[-1]:.3g}", line(high, pitches),
                list(measured)))
    for c in channels:
        if c not in measured:
            out.append((f"{c} at the measured points", conditions, [c]))
    return out


def tightening(model, p_hat: np.ndarray, cov_scaled: np.ndarray, scale: np.ndarray, conditions: OperatingConditions,
               radius: float, measured: list, relative_noise: dict, names: list, best: int = 2,
               field_variance=None) -> dict:
    """For each parameter in ``names``: its σ now and with each candidate group added, best first.

    Parameters
    ----------
    model : ForwardModel
    p_hat : ndarray, shape (n,)
        The estimate [parameter units].
    cov_scaled : ndarray, shape (n, n)
        Its covariance in scaled units [scale units²].
    scale : ndarray, shape (n,)
    conditions : OperatingConditions
        The measured points.
    radius : float
        [m]
    measured : list of str
        The measured channels.
    relative_noise : dict
        Measured channel -> median σ/|y| [-].
    names : list of str
        The parameters asked about.
    best : int
        Groups kept per parameter.
    field_variance : callable, optional
        (conditions, channel indices, evaluation) ↦ variance of those outputs from the correction
        field the nodes do not carry, shape (n_points, n_channels) [channel unit²]: it adds to a
        candidate's noise, since a point where the field is unknown (beyond the nodes) informs a
        parameter only through that uncertainty.

    Returns
    -------
    dict name -> {"sigma": σ now, "groups": [{"what", "sigma", "ratio"}, ...]} [parameter units]
        Only groups that lower σ by at least 5 %; failed candidate points are left out.
    """
    all_channels = [c.name for c in model.channels]
    index = {q.name: j for j, q in enumerate(model.parameters)}
    wanted = [n for n in names if n in index]
    if not wanted:
        return {}
    rho_default = float(np.median(list(relative_noise.values()))) if relative_noise else 0.01
    groups = candidate_groups(conditions, radius, all_channels, measured)
    out = {n: {"sigma": float(np.sqrt(max(cov_scaled[index[n], index[n]], 0.0)) * scale[index[n]]), "groups": []}
           for n in wanted}
    # every group's points in one batch: one model Jacobian and one field-variance call for all of them
    sizes = [len(cond) for _, cond, _ in groups]
    batch = OperatingConditions(*(np.concatenate([np.broadcast_to(getattr(c, f), (len(c),)) for _, c, _ in groups])
                                  for f in CONDITION_FIELDS))
    ev_all, G_all = model.jacobian(p_hat, batch)
    every = list(range(len(all_channels)))
    var_all = field_variance(batch, every, ev_all) if field_variance is not None else None
    starts = np.concatenate([[0], np.cumsum(sizes)])
    for (what, cond, chans), a, b in zip(groups, starts[:-1], starts[1:]):
        cols = [all_channels.index(c) for c in chans]
        y, G = ev_all.values[a:b, cols], G_all[a:b][:, cols, :]
        ok = ev_all.ok[a:b] & np.all(np.isfinite(y), axis=1) & np.all(np.isfinite(G), axis=(1, 2))
        if not ok.any():
            continue
        y, Gs = y[ok], G[ok] * scale                                   # ∂y/∂p̃
        floor = FLOOR * np.max(np.abs(y), axis=0)
        sig = np.array([relative_noise.get(c, rho_default) for c in chans]) * np.maximum(np.abs(y), floor)
        if var_all is not None:
            sig = np.sqrt(sig ** 2 + var_all[a:b][:, cols][ok])
        Gw = (Gs / np.where(sig > 0, sig, np.inf)[:, :, None]).reshape(-1, Gs.shape[-1])
        CG = cov_scaled @ Gw.T
        S = np.eye(Gw.shape[0]) + Gw @ CG
        reduction = np.einsum("ij,ji->i", CG, np.linalg.solve(S, CG.T))
        for n in wanted:
            j = index[n]
            now = max(cov_scaled[j, j], 0.0)
            after = max(now - reduction[j], 0.0)
            if now > 0 and np.sqrt(after / now) <= 0.95:
                out[n]["groups"].append({"what": what, "sigma": float(np.sqrt(after) * scale[j]),
                                         "ratio": float(np.sqrt(after / now))})
    for n in wanted:
        out[n]["groups"] = sorted(out[n]["groups"], key=lambda g: g["ratio"])[:best]
    return out


def sentence(name: str, entry: dict, unit: str = "") -> str:
    """One line: what would tighten ``name``'s σ ("" when nothing would by 5 %)."""
    if not entry.get("groups"):
        return ""
    u = f" {unit}" if unit and unit != "-" else ""
    parts = [f"{g['what']} (σ {entry['sigma']:.2g} → {g['sigma']:.2g}{u})" for g in entry["groups"]]
    return f"To tighten {name}'s σ, measure " + "; or ".join(parts) + "."
