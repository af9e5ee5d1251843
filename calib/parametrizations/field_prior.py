"""The smooth-field prior of the correction field, and the part of the field the nodes cannot carry.

Under the smooth-field prior the node values of a block (lift or drag) are samples of a
stationary field of variance σ_p² with the squared-exponential correlation

.. math::  ρ(Δα, Δη) = exp(−Δα²/(2ℓ_α²) − Δη²/(2ℓ_η²))

(:func:`se_correlation`), its lengths a number of node spacings of the grid
(:func:`spacing_lengths`). The hat functions interpolate the nodal values bilinearly; what
such a field does between the nodes beyond that is the representation variance
(:func:`unresolved_variance`), which the polar bands add and count as prior.

The field between the nodes has physical lengths (:func:`between_node_lengths`): the same number
of spacings of the grid or of :data:`REFERENCE_SPACING`, whichever is longer. A grid finer than
the reference resolves a field of the same lengths better, so its between-node variance falls as it
is refined (as (h/ℓ)⁴ for h ≪ ℓ); on a grid as coarse as the reference or coarser the term is the
prior's own, unchanged. The prior's
correlation matrix over the parameter vector is
:meth:`calib.parametrizations.correction_field.CorrectionField.node_correlation`.

References
----------
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press
(2006), §2.2 and §4.2.
"""

from __future__ import annotations

import numpy as np

from calib.corrections import CorrectionGrid


def se_correlation(d_alpha, d_eta, lengths: tuple[float, float]) -> np.ndarray:
    """Correlation of the smooth-field prior between points Δα [deg] and Δη [-] apart: the
    squared exponential exp(−Δα²/2ℓ_α² − Δη²/2ℓ_η²) with ``lengths`` = (ℓ_α, ℓ_η)
    (Rasmussen & Williams 2006, §4.2) [-]."""
    return np.exp(-0.5 * (np.asarray(d_alpha) / lengths[0]) ** 2 - 0.5 * (np.asarray(d_eta) / lengths[1]) ** 2)


#: Node spacing (α [deg], η [-]) of the grid on which ``prior_correlation`` = 1 was chosen (the
#: wind-tunnel twins of ``workflows/wind_tunnel_hub_loads.toml``: highest marginal likelihood among
#: 0, 1, 1.5, 2 and 3 spacings; :class:`calib.calibration.CalibrationSettings`). The correlation lengths
#: found there, ``prior_correlation`` × these, are the field's physical lengths; a finer grid does not
#: make the true field rougher (issue 41: with lengths in spacings, the between-node σ of a 12 × 5
#: field was that of a 6 × 5 one and the AEP interval over-covered).
REFERENCE_SPACING = (6.0, 0.2)


def between_node_lengths(grid: CorrectionGrid, length: float) -> tuple[float, float]:
    """ℓ_α [deg] and ℓ_η [-] of the field between the nodes: ``length`` times the longer of the
    grid's mean spacing and :data:`REFERENCE_SPACING`, per coordinate.

    Parameters
    ----------
    grid : CorrectionGrid
    length : float
        ``prior_correlation`` [-] (node spacings of the prior on the nodes).

    Returns
    -------
    tuple of float
    """
    own = spacing_lengths(grid, 1.0)
    return (length * max(own[0], REFERENCE_SPACING[0]), length * max(own[1], REFERENCE_SPACING[1]))


def spacing_lengths(grid: CorrectionGrid, length: float) -> tuple[float, float]:
    """ℓ_α [deg] and ℓ_η [-] of the smooth-field prior for ``length`` node spacings.

    Parameters
    ----------
    grid : CorrectionGrid
        The node grid; its mean α and η spacings are the units.
    length : float
        Correlation length in node spacings [-].

    Returns
    -------
    tuple of float
    """
    return (length * float(np.mean(np.diff(grid.alpha_nodes_deg))),
            length * float(np.mean(np.diff(grid.eta_nodes))))


def unresolved_variance(grid: CorrectionGrid, alpha_deg, eta, node_variance: float,
                        correlation_length: float) -> np.ndarray:
    """Variance of the true field between the nodes that the hat functions cannot carry [-²].

    The shape functions interpolate the nodal values bilinearly; a true correction varies
    between the nodes too. With the smooth-field prior (a stationary field of variance
    σ_p² = ``node_variance`` and correlation ρ of :func:`se_correlation`) the error of the
    interpolant Σ_i N_i(x) f(x_i) at x = (α, η) has variance

    .. math::  σ_{rep}^2(x) = σ_p^2 (1 − 2 Σ_i N_i(x) ρ(x, x_i)
                              + Σ_{ij} N_i(x) N_j(x) ρ(x_i, x_j)),

    zero at the nodes and σ_p² far from every node (outside the grid, where no hat
    reaches). With ``correlation_length = 0`` (independent nodes) the field between the
    nodes is taken as uncertain as at a node and independent of the nodes beyond the
    interpolation, σ_rep² = σ_p²(1 − Σ_i N_i²): 0.75 σ_p² at a cell centre, the roughest
    field compatible with the node spacing. With the default correlation length of one
    node spacing it is 0.098 σ_p² at a cell centre of the wind-tunnel study's grid: a
    field that the chosen grid resolves. The lengths are :func:`between_node_lengths`: on a
    grid finer than :data:`REFERENCE_SPACING` the variance falls as the grid is refined.

    Parameters
    ----------
    grid : CorrectionGrid
    alpha_deg, eta : array_like, broadcastable
        Points [deg], [-].
    node_variance : float
        σ_p², the prior variance of a node value [-²].
    correlation_length : float
        ``prior_correlation`` [-] (:func:`between_node_lengths`).

    Returns
    -------
    ndarray, flat over the broadcast shape

    References
    ----------
    C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press
    (2006), §2.2 and §4.2.
    """
    alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
    node, value, _ = grid.basis(alpha_deg, eta)
    value = value.reshape(-1, 4)
    if not correlation_length > 0:
        return node_variance * np.clip(1.0 - (value ** 2).sum(-1), 0.0, 1.0)
    lengths = between_node_lengths(grid, correlation_length)
    node = node.reshape(-1, 4)
    an = grid.alpha_nodes_deg[node // grid.n_eta]
    en = grid.eta_nodes[node % grid.n_eta]
    a, e = alpha_deg.reshape(-1, 1), eta.reshape(-1, 1)
    rho_x = se_correlation(a - an, e - en, lengths)
    rho_nn = se_correlation(an[:, :, None] - an[:, None, :], en[:, :, None] - en[:, None, :], lengths)
    rel = 1.0 - 2.0 * (value * rho_x).sum(-1) + np.einsum("ki,kij,kj->k", value, rho_nn, value)
    return node_variance * np.clip(rel, 0.0, 1.0)
