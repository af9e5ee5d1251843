"""Identifiability: Fisher matrix, Cramér–Rao bound, whitened SVD, eigenshapes, verdicts (the
retained directions that a point near a fold of the BEM equations determines are found by
:mod:`calib.calibration.fold_directions`, the covariance the frozen directions' curvature adds by
:mod:`calib.calibration.frozen_curvature`).

Notes
-----
With output noise v_k ~ N(0, R) and sensitivities G = ∂y/∂p stacked over the operating
points, the Fisher information is F = Gᵀ R⁻¹ G and the Cramér–Rao bound Cov(p̂) ≥ F⁻¹.
Parameters with different units are first scaled, p̃ = (p − p₀)/scale, and the SVD is
taken of the whitened, scaled sensitivities

.. math::  M = R^{-1/2} G D = U S V^T,\\qquad D = \\mathrm{diag}(scale),

so that the scaled Fisher matrix is F̃ = V S² Vᵀ. The new parameters θ = Vᵀ p̃ are
statistically independent with σ(θ_i) = 1/s_i. Those with σ(θ_i) <= σ̄ are retained;
the others are frozen at 0 (nominal). The *eigenshape* of θ_i is the correction pattern
it moves, ψ_i(α, η) = Σ_jl N_j(α) H_l(η) (v_i)_jl, for the lift and drag blocks
separately (Bottasso, Cacciola & Iriarte 2014, §3).

References
----------
C.L. Bottasso, S. Cacciola, X. Iriarte, Calibration of wind turbine lifting line models
from rotor loads, J. Wind Eng. Ind. Aerodyn. 124 (2014) 29-45.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import stats

from calib.errors import InputError
from calib.types import Parameter, ParameterKind

VERDICTS = ("identified", "poorly observable", "at bound", "confounded")


def whitened_sensitivities(G: np.ndarray, sigma: np.ndarray, scale: np.ndarray,
                           ok: np.ndarray | None = None) -> np.ndarray:
    """The whitened, scaled sensitivity matrix M = R^(−½) G D.

    Parameters
    ----------
    G : ndarray, shape (n_points, n_channels, n_params)
        ∂y/∂p [channel unit / parameter unit].
    sigma : ndarray, shape (n_points, n_channels)
        1-σ noise [channel unit] (diagonal R).
    scale : ndarray, shape (n_params,)
        Parameter scales [parameter unit].
    ok : ndarray of bool, shape (n_points,), optional
        Points to keep (converged ones); the others get zero rows.

    Returns
    -------
    ndarray, shape (n_points * n_channels, n_params)
        Rows point-major.
    """
    M = G * scale[None, None, :] / sigma[:, :, None]
    if ok is not None:
        M = np.where(ok[:, None, None], M, 0.0)
    M = np.nan_to_num(M, nan=0.0, posinf=0.0, neginf=0.0)
    return M.reshape(-1, G.shape[-1])


def fisher_matrix(M: np.ndarray) -> np.ndarray:
    """Scaled Fisher information F̃ = Mᵀ M, shape (n_params, n_params) [1/scale²]."""
    return M.T @ M


def cramer_rao(F: np.ndarray, rcond: float = 1e-12):
    """Cramér–Rao bound, standard deviations and correlation matrix.

    Parameters
    ----------
    F : ndarray, shape (n, n)
        Fisher matrix.
    rcond : float
        Relative cut-off of the pseudo-inverse; directions below it get infinite variance.

    Returns
    -------
    cov : ndarray, shape (n, n)
        F⁺ (pseudo-inverse; ``inf`` on the diagonal for unobservable parameters).
    std : ndarray, shape (n,)
    correlation : ndarray, shape (n, n)
        χ_pq = (F⁻¹)_pq / √((F⁻¹)_pp (F⁻¹)_qq); NaN for unobservable parameters.
    """
    w, V = np.linalg.eigh(0.5 * (F + F.T))
    wmax = max(float(w.max(initial=0.0)), 0.0)
    keep = w > rcond * wmax if wmax > 0 else np.zeros_like(w, bool)
    cov = (V[:, keep] / w[keep]) @ V[:, keep].T
    # a parameter touched by a null direction has unbounded variance
    null_weight = (V[:, ~keep] ** 2).sum(axis=1)
    var = np.diag(cov).copy()
    var[null_weight > 1e-8] = np.inf
    std = np.sqrt(var)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr[~np.isfinite(std), :] = np.nan
    corr[:, ~np.isfinite(std)] = np.nan
    cov = cov.copy()
    cov[np.diag_indices_from(cov)] = var
    return cov, std, corr


@dataclass(frozen=True, eq=False)
class SvdAnalysis:
    """SVD of the whitened, scaled sensitivities and the retained set.

    Attributes
    ----------
    singular_values : ndarray, shape (n_params,)
        s_i, descending (zero-padded when there are fewer rows than parameters) [1/scale].
    V : ndarray, shape (n_params, n_params)
        Right singular vectors as columns; θ = Vᵀ p̃.
    sigma_theta : ndarray, shape (n_params,)
        σ(θ_i) = 1/s_i [scale units] (inf for s_i = 0).
    sigma_bar : float
        Threshold: θ_i is retained when σ(θ_i) <= σ̄.
    retained : ndarray of bool, shape (n_params,)
    """

    singular_values: np.ndarray
    V: np.ndarray
    sigma_theta: np.ndarray
    sigma_bar: float
    retained: np.ndarray

    @property
    def n_retained(self) -> int:
        return int(self.retained.sum())

    @property
    def basis(self) -> np.ndarray:
        """V_ID, the retained columns, shape (n_params, n_retained)."""
        return self.V[:, self.retained]


def svd_analysis(M: np.ndarray, sigma_bar: float, max_retained: int | None = None) -> SvdAnalysis:
    """SVD of M and selection of the parameters with σ(θ_i) = 1/s_i <= σ̄.

    Parameters
    ----------
    M : ndarray, shape (m, n_params)
        Whitened, scaled sensitivities (:func:`whitened_sensitivities`).
    sigma_bar : float
        Largest acceptable standard deviation of a retained θ, in units of the
        parameter scales [-]. ``inf`` retains every direction with s_i > 0.
    max_retained : int, optional
        Cap on the number retained.
    """
    if not sigma_bar > 0:
        raise InputError(f"sigma_bar must be > 0, got {sigma_bar!r}", "svd_analysis", field="sigma_bar")
    n = M.shape[1]
    _, s, Vt = np.linalg.svd(M, full_matrices=True)
    s_full = np.zeros(n)
    s_full[: s.size] = s
    # deterministic sign: largest component of each vector positive
    V = Vt.T.copy()
    signs = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(n)])
    V *= np.where(signs == 0, 1.0, signs)
    tiny = 1e-12 * max(float(s_full[0]) if n else 0.0, 1e-300)
    with np.errstate(divide="ignore"):
        sig = np.where(s_full > tiny, 1.0 / np.where(s_full > tiny, s_full, 1.0), np.inf)
    retained = np.isfinite(sig) & (sig <= sigma_bar)
    if max_retained is not None and retained.sum() > max_retained:
        retained[np.flatnonzero(retained)[max_retained:]] = False
    return SvdAnalysis(s_full, V, sig, float(sigma_bar), retained)


def sigma_bar_for(smallest_correction: float, confidence: float = 0.95) -> float:
    """Threshold σ̄ from the smallest correction worth identifying.

    A θ_i is kept when a change of size ``smallest_correction`` (in scale units) is
    distinguishable from zero at the two-sided ``confidence`` level:
    σ̄ = smallest_correction / z_{(1+confidence)/2}.
    """
    return float(smallest_correction / stats.norm.ppf(0.5 * (1.0 + confidence)))


def subspace_cosines(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Cosines of the principal angles between the column spaces of orthonormal A and B."""
    if A.shape[1] == 0 or B.shape[1] == 0:
        return np.ones(0)
    return np.clip(np.linalg.svd(A.T @ B, compute_uv=False), 0.0, 1.0)


def observability(V: np.ndarray, retained: np.ndarray) -> np.ndarray:
    """Fraction of each scaled parameter's direction inside the retained subspace [-].

    o_j = Σ_{i retained} V_ji² ∈ [0, 1]: 1 means the data determine p̃_j through the
    retained θ, 0 means p̃_j is frozen at nominal.
    """
    return (V[:, retained] ** 2).sum(axis=1)


def frozen_aware_covariance(V: np.ndarray, sigma_theta: np.ndarray, retained: np.ndarray,
                            prior: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r"""Covariance of the truncated estimate that accounts for the frozen directions.

    The truncated-SVD estimate sets θ_NID = V_NIDᵀ p̃ to 0 (nominal); the truth has
    components there too. With a Gaussian prior p̃ ~ N(0, P) (P = diag(prior_std²) for
    independent parameters, or a full matrix such as the smooth-field prior), the
    frozen coordinates have prior covariance V_NIDᵀ P V_NID, so the error of p̃̂ has

    .. math::  Cov(p̃̂) = V_{ID}\,diag(σ(θ_{ID})^2)\,V_{ID}^T
                        + V_{NID} (V_{NID}^T P V_{NID}) V_{NID}^T

    (docs/theory.md, Uncertainty). In a linear model the two parts are exact and uncorrelated:
    the retained θ̂ are unbiased whatever the frozen components are, because U_ID ⟂ U_NID.
    Where the data say nothing the band is as wide as the prior. A model that is not linear
    over the prior's range adds :func:`frozen_curvature_covariance`.

    Parameters
    ----------
    V : ndarray, shape (n, n)
        Right singular vectors (columns) of the whitened scaled sensitivities.
    sigma_theta : ndarray, shape (n,)
        σ(θ_i) = 1/s_i [scale units].
    retained : ndarray of bool, shape (n,)
    prior : ndarray, shape (n,) or (n, n)
        Prior 1-σ of each scaled parameter [scale units], or the prior covariance P of the
        scaled parameters [scale units²].

    Returns
    -------
    cov_retained, cov_frozen : ndarray, shape (n, n)
        The two parts in scaled units; their sum is Cov(p̃̂).
    """
    Vr, Vn = V[:, retained], V[:, ~retained]
    cov_retained = (Vr * sigma_theta[retained] ** 2) @ Vr.T
    cov_frozen = Vn @ prior_in(Vn, prior) @ Vn.T
    return cov_retained, cov_frozen


def prior_in(Vn: np.ndarray, prior: np.ndarray) -> np.ndarray:
    """Prior covariance of the coordinates along the columns of ``Vn``: Vnᵀ P Vn, with P a
    matrix [scale units²] or the 1-σ of independent parameters [scale units]."""
    prior = np.asarray(prior, float)
    return Vn.T @ prior @ Vn if prior.ndim == 2 else (Vn.T * prior ** 2) @ Vn


def _ranges(values: np.ndarray) -> str:
    lo, hi = float(np.min(values)), float(np.max(values))
    return f"{lo:g}" if np.isclose(lo, hi) else f"{lo:g}–{hi:g}"


def confounding(F: np.ndarray, prior_std: np.ndarray, parameters: Sequence[Parameter],
                correlation_fraction: float = 0.5) -> dict[str, dict]:
    """How much of each non-field parameter's information the correction field shares.

    With the prior-regularized information A = F̃ + P⁻¹ (scaled units), the variance of
    parameter j with every other parameter free is (A⁻¹)_jj and with the others fixed
    1/A_jj. The *variance inflation* VIF_j = (A⁻¹)_jj A_jj ≥ 1, and the share of its
    information taken by the others is 1 − 1/VIF_j. The share taken by the correction field
    alone uses the sub-matrix of {j} ∪ field. The field nodes most correlated with j (|ρ| ≥
    ``correlation_fraction`` × the largest) say where: "lift, η 0.8–1.0, α 4–12 deg".

    Parameters
    ----------
    F : ndarray, shape (n, n)
        Scaled Fisher information F̃ = MᵀM.
    prior_std : ndarray, shape (n,)
        Prior 1-σ of each scaled parameter [scale units].
    parameters : sequence of Parameter

    Returns
    -------
    dict name -> dict
        For every parameter that is not a correction node: ``variance_inflation``,
        ``shared_information`` (with all others), ``shared_with_field``, ``region`` (text,
        "" without a field) and ``correlated_nodes`` (names).
    """
    A = F + np.diag(1.0 / prior_std ** 2)
    C = np.linalg.inv(A)
    field_idx = np.array([j for j, q in enumerate(parameters)
                          if q.kind in (ParameterKind.LIFT_CORRECTION, ParameterKind.DRAG_CORRECTION)], int)
    out = {}
    for j, q in enumerate(parameters):
        if j in set(field_idx.tolist()):
            continue
        vif = float(C[j, j] * A[j, j])
        entry = {"variance_inflation": vif, "shared_information": 1.0 - 1.0 / vif, "shared_with_field": 0.0,
                 "region": "", "correlated_nodes": []}
        if field_idx.size:
            sub = np.concatenate([[j], field_idx])
            Cs = np.linalg.inv(A[np.ix_(sub, sub)])
            entry["shared_with_field"] = 1.0 - 1.0 / float(Cs[0, 0] * A[j, j])
            # an ill-conditioned A can give a variance ≤ 0 by round-off: no correlation stated there
            var = C[j, j] * np.diag(C)[field_idx]
            rho = np.where(var > 0, C[j, field_idx] / np.sqrt(np.where(var > 0, var, 1.0)), 0.0)
            strong = np.abs(rho) >= correlation_fraction * np.max(np.abs(rho)) if np.any(rho) else rho != 0
            parts = []
            for kind, label in ((ParameterKind.LIFT_CORRECTION, "lift"), (ParameterKind.DRAG_CORRECTION, "drag")):
                sel = [int(field_idx[k]) for k in np.flatnonzero(strong) if parameters[field_idx[k]].kind == kind]
                if sel:
                    parts.append(f"{label} near η {_ranges(np.array([parameters[i].eta for i in sel]))}, "
                                 f"α {_ranges(np.array([parameters[i].alpha_deg for i in sel]))} deg")
            entry["region"] = "; ".join(parts)
            entry["correlated_nodes"] = [parameters[int(field_idx[k])].name for k in np.flatnonzero(strong)]
        out[q.name] = entry
    return out


def parameter_verdicts(parameters: Sequence[Parameter], p_hat: np.ndarray, lower: np.ndarray,
                       upper: np.ndarray, std: np.ndarray, prior_std: np.ndarray,
                       obs: np.ndarray | None = None, confounded: dict | None = None,
                       identified_ratio: float = 0.5, confounded_share: float = 0.75,
                       bound_tolerance: float = 1e-3) -> list[dict]:
    """A plain verdict per physical parameter, from its posterior and prior.

    Rules (in this order)
    ---------------------
    - ``at bound``: the estimate is within ``bound_tolerance`` × scale of a bound.
    - ``confounded``: a non-field parameter that shares at least ``confounded_share`` of its
      information with the other parameters (see :func:`confounding`).
    - ``identified``: posterior σ ≤ ``identified_ratio`` × prior σ (the data, not the prior,
      determine it).
    - ``poorly observable``: otherwise. Its band stays close to the prior's width; an
      estimate more than 2σ from nominal is said so in ``note`` (it is not "frozen").

    Parameters
    ----------
    std, prior_std : ndarray, shape (n,)
        Posterior and prior 1-σ in parameter units.
    obs : ndarray, shape (n,), optional
        Observability (fraction inside the retained subspace), reported alongside.
    confounded : dict, optional
        Output of :func:`confounding`.

    Returns
    -------
    list of dict
        name, kind, verdict, value, nominal, std, prior_std, std_ratio, observability, lower,
        upper, unit, note (and shared_information, confounded_with for non-field parameters).
    """
    out = []
    confounded = confounded or {}
    for j, q in enumerate(parameters):
        tol = bound_tolerance * q.scale
        ratio = float(std[j] / prior_std[j])
        c = confounded.get(q.name)
        if p_hat[j] <= lower[j] + tol or p_hat[j] >= upper[j] - tol:
            verdict = "at bound"
        elif c is not None and c["shared_information"] >= confounded_share:
            verdict = "confounded"
        elif ratio <= identified_ratio:
            verdict = "identified"
        else:
            verdict = "poorly observable"
        shift = (p_hat[j] - q.nominal) / std[j] if std[j] > 0 else 0.0
        note = f"{abs(shift):.1f}σ from nominal" if abs(shift) > 2.0 else ""
        d = {"name": q.name, "kind": str(q.kind), "verdict": verdict, "value": float(p_hat[j]),
             "nominal": float(q.nominal), "std": float(std[j]), "prior_std": float(prior_std[j]),
             "std_ratio": ratio, "observability": float(obs[j]) if obs is not None else float("nan"),
             "lower": float(lower[j]), "upper": float(upper[j]), "unit": q.unit, "note": note}
        if c is not None:
            d["shared_information"] = c["shared_information"]
            d["shared_with_field"] = c["shared_with_field"]
            d["confounded_with"] = c["region"]
        out.append(d)
    return out
