"""Section sensitivities at the BEM root and their projection on the chain's parameters.

At a converged section R(φ*, c) = 0, so for every derivative column c (pitch, inflow speed,
effect parameters or probes) dφ*/dc = −(∂R/∂φ)⁻¹ ∂R/∂c (implicit function theorem, Ning
2014), and a section quantity Q has the total derivative dQ/dc = ∂Q/∂c + ∂Q/∂φ dφ*/dc.
Conditions-stage parameters act on the whole point through the inflow speed V and the
pitch β: dQ/dp = dQ/dV dV/dp + dQ/dβ dβ/dp, with dV/dp and dβ/dp per point (which also
carry the fixed-point feedback of effects that read the thrust, see
:func:`calib.bem.solver.solve_bem`). Every rotor output is a linear functional of section
quantities, so :func:`project` maps the section derivatives on the parameters with the
same station weights as the values.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.bem.stages import ProbeMap


@dataclass(frozen=True, eq=False)
class Block:
    """The derivative columns of one section-stage effect.

    Attributes
    ----------
    offset, n_params : int
        Its parameters' slice of ``p``.
    column, n_columns : int
        Its columns in :attr:`SectionSensitivities.columns` (after the pitch and wind columns).
    probe_map : ProbeMap or None
        For a probed effect: arrays of shape (n_points, n_sectors, n_stations, m).
    effect : str
        The effect's name.
    """

    offset: int
    n_params: int
    column: int
    n_columns: int
    probe_map: ProbeMap | None = None
    effect: str = ""


@dataclass(frozen=True, eq=False)
class SectionSensitivities:
    """Total derivatives of section quantities at the BEM root.

    Attributes
    ----------
    columns : dict
        Quantity (``Np``, ``Tp`` [N/m], ``cn``, ``ct`` [-] in chord axes, ``alpha_deg``) ->
        ndarray (n_points, n_sectors, n_stations, n_columns): column 0 per degree of pitch,
        column 1 per m/s of inflow speed, then the section-stage effects' columns (zero at
        unloaded and failed sections).
    pitch, wind_speed : ndarray, shape (n_points, n_params)
        Total derivatives of each point's pitch [deg] and inflow speed [m/s] after the
        conditions stage with respect to ``p``.
    blocks : tuple of Block
    n_params : int
    alpha_deg : ndarray, shape (n_points, n_sectors, n_stations) or None
        The angle of attack of every converged section at the root [deg], NaN elsewhere (where the
        probes read the polars: :func:`project_probes` maps them on another grid's nodes).
    """

    columns: dict
    pitch: np.ndarray
    wind_speed: np.ndarray
    blocks: tuple
    n_params: int
    alpha_deg: np.ndarray | None = None


def project(sens: SectionSensitivities, quantity: str, weights: np.ndarray) -> np.ndarray:
    """d/dp of Σ_sectors Σ_stations w_i Q[k, s, i] for every point.

    Parameters
    ----------
    sens : SectionSensitivities
    quantity : str
        Key of ``sens.columns``.
    weights : ndarray, shape (n_stations,)
        Station weights of the functional (e.g. integration weights of the thrust).

    Returns
    -------
    ndarray, shape (n_points, n_params)
    """
    D = sens.columns[quantity]
    Dw = np.einsum("ksic,i->kc", D, weights)
    G = Dw[:, [0]] * sens.pitch + Dw[:, [1]] * sens.wind_speed
    for b in sens.blocks:
        if b.probe_map is None:
            G[:, b.offset:b.offset + b.n_params] += Dw[:, b.column:b.column + b.n_columns]
        else:
            G[:, b.offset:b.offset + b.n_params] += project_probes(D, b.column, b.probe_map, weights, b.n_params)
    return G


def project_probes(D: np.ndarray, column: int, probe_map: ProbeMap, weights: np.ndarray, n_out: int) -> np.ndarray:
    """d/dq of Σ_sectors Σ_stations w_i Q[k, s, i] for the n_out parameters q that reach the sections
    through probes, ``d Q / d q[index[..., m]] += weight[..., m] d Q / d probe[probe[m]]``
    (:class:`calib.bem.stages.ProbeMap`).

    Parameters
    ----------
    D : ndarray, shape (n_points, n_sectors, n_stations, n_columns)
        A quantity's section derivatives (:attr:`SectionSensitivities.columns`).
    column : int
        The column of probe 0.
    probe_map : ProbeMap
        Arrays of shape (n_points, n_sectors, n_stations, m), zero weight at inactive sections.
    weights : ndarray, shape (n_stations,)
    n_out : int

    Returns
    -------
    ndarray, shape (n_points, n_out)
    """
    n_pts = D.shape[0]
    pm = probe_map
    contrib = D[..., column + pm.probe] * weights[None, None, :, None] * pm.weight
    flat = (np.arange(n_pts)[:, None, None, None] * n_out + pm.index).reshape(-1)
    return np.bincount(flat, contrib.reshape(-1), n_pts * n_out).reshape(n_pts, n_out)
