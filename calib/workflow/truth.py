"""Synthetic truths of a workflow (``[truth]``): a smooth correction field of Gaussian bumps, its
model, and statements of a result against it (band coverage, nuisance errors)."""

from __future__ import annotations

import numpy as np

from calib.corrections import CorrectionGrid
from calib.models.bem_model import BemModel
from calib.types import nominal_vector
from calib.workflow.sections import Truth


def smooth_field(bumps, alpha_deg, eta):
    """ΔC_L, ΔC_D of a sum of smooth bumps (Gaussian in α; Gaussian or smooth box in η).

    Parameters
    ----------
    bumps : sequence of calib.workflow.sections.Bump
        A bump with ``eta_range = (a, b)`` is a box in η with tanh edges of width ``edge_width``
        [-], to localize a correction on one airfoil's span range.
    alpha_deg, eta : array_like
        Angles of attack [deg] and spanwise positions r/R [-] (broadcast together).

    Returns
    -------
    dcl, dcd : ndarray
        ΔC_L and ΔC_D [-] at the points.
    """
    alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
    out = {"lift": np.zeros(alpha_deg.shape), "drag": np.zeros(alpha_deg.shape)}
    for b in bumps:
        fa = np.exp(-0.5 * ((alpha_deg - b.alpha_deg) / b.alpha_width) ** 2)
        if b.eta_range is not None:
            lo, hi = b.eta_range
            w = b.edge_width
            fe = 0.25 * (1 + np.tanh((eta - lo) / w)) * (1 - np.tanh((eta - hi) / w))
        else:
            fe = np.exp(-0.5 * ((eta - b.eta) / b.eta_width) ** 2)
        out[b.block] += b.amplitude * fa * fe
    return out["lift"], out["drag"]


def truth_model(rotor, channels, settings, truth: Truth, nuisance):
    """A BemModel whose fine correction grid samples the smooth truth field of ``truth``, and its p (the
    ``nuisance`` parameters at their true values where ``truth`` gives them)."""
    da = float(truth.alpha_step_deg)
    de = float(truth.eta_step)
    grid = CorrectionGrid(np.arange(-30.0, 60.0 + da / 2, da), np.arange(0.0, 1.0 + de / 2, de),
                          cl_bound=10.0, cd_bound=10.0)
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    dcl, dcd = smooth_field(truth.bumps, A, E)
    model = BemModel(rotor, grid, channels, settings, nuisance)
    p = nominal_vector(model.parameters)
    p[:grid.n_lift] = dcl.reshape(-1)
    p[grid.n_lift:grid.n_params] = dcd.reshape(-1)
    true_values = truth.nuisance_values()
    for j, name in enumerate(nuisance):
        if name in true_values:
            p[grid.n_params + j] = float(true_values[name])
    return model, p


def truth_checks(model, result, truth: Truth) -> dict[str, str]:
    """Statements about a synthetic run against its known truth: band coverage, nuisance errors.

    Coverage is counted at the (α, η) points the operating points reach, with the same bands
    the report draws (frozen-direction prior and representation variance included).
    """
    out = {}
    if model.capabilities.correction_field and result.fit.alpha_seen.size:
        field = model.correction_field()
        a, e = result.fit.alpha_seen, result.fit.eta_seen
        tl, td = smooth_field(truth.bumps, a, e)
        prior = result.uncertainty.prior_std if result.provenance.settings.get("representation_error", True) else None
        # a result saved before the smooth-field prior had independent nodes (correlation length 0)
        cov = field.coverage(result.estimate.p_hat, result.uncertainty.cov_p, a, e, tl, td,
                             result.provenance.settings.get("band_confidence", 0.95),
                             prior, correlation_length=float(result.provenance.settings.get("prior_correlation", 0.0)),
                             cd_min=result.provenance.settings.get("cd_min"))
        out["coverage of the known truth"] = (
            f"the {100 * cov['confidence']:.0f} % bands contain the true ΔC_L at {100 * cov['lift']:.1f} % and the "
            f"true ΔC_D at {100 * cov['drag']:.1f} % of the {cov['n_points']} (α, η) points the operating points reach")
    true_values = truth.nuisance_values()
    for v in result.identifiability.verdicts:
        if v["name"] in true_values and v["std"] > 0:
            z = (v["value"] - float(true_values[v["name"]])) / v["std"]
            out[f"{v['name']} against its truth"] = (f"estimate {v['value']:.4g} ± {v['std']:.2g} {v['unit']}, truth "
                                                     f"{float(true_values[v['name']]):.4g}: {z:+.1f}σ")
    return out


