r"""Design criteria on the posterior precision of the prior-whitened scaled parameters, with the
block (Woodbury) updates greedy selection and exchange need.

Notes
-----
With the prior P = L Lᵀ of the scaled parameters p̃ (:meth:`calib.calibration.calibrator.Calibrator.prior_cov_scaled`)
and the whitened coordinates w = L⁻¹ p̃, a candidate point j with the (noise-)whitened scaled
sensitivities M_j = R_j^{-½} ∂y_j/∂p̃ contributes the block H_j = M_j L (m_j rows), and a design ξ
(a multiset of candidates) has the posterior precision

.. math::  A(ξ) = I + Σ_{j∈ξ} H_jᵀ H_j ,\qquad \mathrm{Cov}(p̃ \mid ξ) = L A(ξ)^{-1} Lᵀ

(the linear-Gaussian posterior; Chaloner & Verdinelli 1995, eq. 3). Bayesian D-optimality
maximizes log det A(ξ) (= log det(P⁻¹ + Σ G_jᵀR_j⁻¹G_j) + log det P); the "A-type" criteria
minimize tr(Cᵀ A(ξ)⁻¹ C) for a matrix C: the named parameters' posterior variances relative to
their prior ones (C = Lᵀ E D⁻¹), or the prediction variance of target outputs relative to their
noise (C = Lᵀ M_tᵀ). Adding a block H changes them by

.. math::  Δ_D = \log\det(I + S),\qquad Δ_A = \mathrm{tr}\big(Zᵀ Hᵀ (I + S)^{-1} H Z\big),
           \quad S = H A^{-1} Hᵀ,\ Z = A^{-1} C,

and A⁻¹ follows by the Woodbury identity, A⁻¹ − A⁻¹Hᵀ(I + S)⁻¹HA⁻¹ (removing a block: the signs
flip, I − S). Every candidate's gain is one batched product over the candidates.

References
----------
K. Chaloner, I. Verdinelli, Bayesian experimental design: a review, Statistical Science 10
(1995) 273-304.
V.V. Fedorov, Theory of Optimal Experiments, Academic Press (1972), ch. 2-3 (the exchange algorithm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Criterion", "d_criterion", "a_criterion", "woodbury", "log_det", "determined_directions"]


def log_det(A: np.ndarray) -> float:
    """log det of a symmetric positive definite matrix (by Cholesky), averaged over any leading
    (prior-draw) axes [-]."""
    L = np.linalg.cholesky(A)
    return float(np.mean(2.0 * np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)))


def _t(X: np.ndarray) -> np.ndarray:
    return np.swapaxes(X, -1, -2)


def woodbury(Ainv: np.ndarray, H: np.ndarray, sign: float = 1.0) -> np.ndarray:
    """(A + sign·HᵀH)⁻¹ from A⁻¹ by the Woodbury identity.

    Parameters
    ----------
    Ainv : ndarray, shape (..., n, n)
        A⁻¹ (symmetric positive definite); leading axes: prior draws.
    H : ndarray, shape (..., m, n)
        The block added (sign +1) or removed (sign −1).
    sign : float
        +1 or −1.
    """
    K = H @ Ainv
    S = np.eye(H.shape[-2]) + sign * (K @ _t(H))
    out = Ainv - sign * _t(K) @ np.linalg.solve(S, K)
    return 0.5 * (out + _t(out))


def _schur(Ainv: np.ndarray, H: np.ndarray, sign: float = 1.0):
    """K = H A⁻¹ and I + sign·H A⁻¹ Hᵀ for a batch of blocks H, shape (..., n_c, m, n)."""
    K = H @ Ainv[..., None, :, :]
    return K, np.eye(H.shape[-2]) + sign * (K @ _t(H))


def _mean_over_draws(x: np.ndarray, n_c: int) -> np.ndarray:
    return x.reshape(-1, n_c).mean(axis=0)


@dataclass(frozen=True)
class Criterion:
    """A design criterion: larger ``value`` is better.

    Attributes
    ----------
    kind : {"d", "a"}
        Bayesian D (log det A) or an A-type trace tr(Cᵀ A⁻¹ C) (its value is −trace).
    C : ndarray, shape (n, k) or None
        The A-type weight matrix in whitened coordinates (None for D).
    name : str
        In words, for the report.
    """

    kind: str
    C: np.ndarray | None = None
    name: str = "Bayesian D-optimality"

    def value(self, A: np.ndarray, Ainv: np.ndarray | None = None) -> float:
        """The criterion at precision A [-]."""
        if self.kind == "d":
            return log_det(A)
        Ainv = np.linalg.inv(A) if Ainv is None else Ainv
        return -float(np.mean(np.sum(self.C * (Ainv @ self.C), axis=(-2, -1))))

    def gains(self, Ainv: np.ndarray, H: np.ndarray) -> np.ndarray:
        """The change of ``value`` from adding each block of ``H`` alone, shape (n_c,).

        Parameters
        ----------
        Ainv : ndarray, shape (..., n, n)
        H : ndarray, shape (..., n_c, m, n)
            Candidate blocks (whitened); leading axes: prior draws, over which the gain is averaged
            (the pseudo-Bayesian criterion).
        """
        n_c = H.shape[-3]
        K, S = _schur(Ainv, H, 1.0)
        if self.kind == "d":
            return _mean_over_draws(np.linalg.slogdet(S)[1], n_c)
        HZ = K @ self.C                                          # H A⁻¹ C, (..., n_c, m, k)
        return _mean_over_draws(np.sum(HZ * np.linalg.solve(S, HZ), axis=(-2, -1)), n_c)

    def removal(self, Ainv: np.ndarray, H: np.ndarray) -> float:
        """The change of ``value`` from removing block ``H`` (..., m, n) from the design (≤ 0)."""
        K, S = _schur(Ainv, H[..., None, :, :], -1.0)
        if self.kind == "d":
            sign, ld = np.linalg.slogdet(S)
            return float(np.mean(ld)) if np.all(sign > 0) else -np.inf
        HZ = K @ self.C
        return -float(np.mean(np.sum(HZ * np.linalg.solve(S, HZ), axis=(-2, -1))))


def d_criterion() -> Criterion:
    """Bayesian D-optimality: log det of the whitened posterior precision."""
    return Criterion("d")


def a_criterion(C: np.ndarray, name: str) -> Criterion:
    """An A-type criterion tr(Cᵀ A⁻¹ C) (minimized) with weight matrix ``C`` (n, k)."""
    C = np.asarray(C, float)
    if C.ndim != 2 or C.shape[1] == 0:
        raise ValueError("a_criterion needs a weight matrix of shape (n_params, k >= 1)")
    return Criterion("a", C, name)


def determined_directions(F: np.ndarray) -> np.ndarray:
    """Singular values s of the prior-whitened sensitivities of a design from its whitened Fisher
    matrix F = Σ H_jᵀH_j (s² its eigenvalues), descending; the data determine the directions with
    s > 1 better than the prior (the MAP's convention, :func:`calib.calibration.uncertainty.laplace_covariance`)."""
    lam = np.linalg.eigvalsh(0.5 * (F + F.T))[::-1]
    return np.sqrt(np.clip(lam, 0.0, None))
