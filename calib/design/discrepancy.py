r"""Model discrepancy over the operating plane in a design criterion (Kennedy & O'Hagan 2001).

A variance criterion that trusts the model's form treats every point as independent given the
parameters, so it piles the points where the sensitivities are largest, the edges of the envelope,
and learns nothing between them. If the outputs also carry a smooth discrepancy δ_c(x) over the
operating plane x = (λ, pitch, rotor speed, yaw), each coordinate scaled to [0, 1] over the envelope,

.. math::  y_c(x) = η_c(x; p) + δ_c(x) + ε_c,\quad δ_c \sim \mathrm{GP}(0, τ_c^2 k),\quad
           k(x, x') = \exp\!\big(-\lVert x - x' \rVert^2 / (2\ell^2)\big),\quad τ_c = κ σ_c ,

then neighbouring points share their δ and stop counting as independent evidence. The GP is carried
by a low-rank (subset-of-regressors) basis on a grid Z of inducing points, δ_c(x) ≈ τ_c φ(x)ᵀ b_c,
φ(x)ᵀ = k(x, Z) K_ZZ^{-½}, b_c ~ N(0, I) (Quiñonero-Candela & Rasmussen 2005), so the whitened block
of a point gains the columns κ φ(x)ᵀ per channel and the design criterion acts on the augmented
precision of (parameters, b): the block-additive structure greedy and exchange need is kept.

References
----------
M.C. Kennedy, A. O'Hagan, Bayesian calibration of computer models, J. R. Stat. Soc. B 63 (2001)
425-464.
J. Quiñonero-Candela, C.E. Rasmussen, A unifying view of sparse approximate Gaussian process
regression, J. Mach. Learn. Res. 6 (2005) 1939-1959.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calib.design.candidates import Envelope
from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["Discrepancy", "basis", "augment", "parse_discrepancy"]

#: Inducing points at most (over the active axes of the envelope).
MAX_INDUCING = 64

#: An axis of the envelope is an axis of the discrepancy when its range exceeds this: a fraction of λ's and of
#: the rotor speed's upper end, degrees of pitch and yaw (a measured table's scatter about one setting is no axis).
MIN_SPAN = {"tsr": 0.02, "pitch": 0.5, "rotor_speed": 0.02, "yaw": 1.0}


@dataclass(frozen=True)
class Discrepancy:
    """The discrepancy's prior.

    Attributes
    ----------
    scale : float
        κ = τ_c/σ_c: its standard deviation relative to each channel's noise σ_c [-].
    length : float
        Correlation length ℓ as a fraction of the envelope's range on every axis [-].
    """

    scale: float = 1.0
    length: float = 0.25

    def __post_init__(self):
        for key, v in (("scale", self.scale), ("length", self.length)):
            if not np.isfinite(v) or v <= 0:
                raise InputError(f"the discrepancy's {key} must be a number > 0, got {v!r}", "--discrepancy",
                                 field=key)


def parse_discrepancy(text: str, source: str = "--discrepancy") -> Discrepancy | None:
    """``SCALE[:LENGTH]`` (e.g. ``1:0.25``) or ``none``."""
    t = str(text).strip().lower()
    if t in ("none", "off", "0"):
        return None
    try:
        vals = [float(x) for x in t.split(":")]
        if len(vals) not in (1, 2):
            raise ValueError
    except ValueError:
        raise InputError(f"{source} {text!r}: expected SCALE[:LENGTH] (relative to the noise, a fraction of the "
                         "envelope), e.g. 1:0.25, or none", source, field="discrepancy") from None
    return Discrepancy(*vals)


def _unit(cond: OperatingConditions, env: Envelope) -> np.ndarray:
    """The active coordinates (those the envelope spans by more than :data:`MIN_SPAN`) scaled to [0, 1] over
    the envelope, shape (n_points, n_axes)."""
    X = np.column_stack([cond.tip_speed_ratio(env.radius), cond.pitch, cond.rotor_speed, cond.yaw])
    lo = np.array([env.tsr[0], env.pitch[0], env.rotor_speed[0], env.yaw[0]])
    hi = np.array([env.tsr[1], env.pitch[1], env.rotor_speed[1], env.yaw[1]])
    active = (hi - lo) > np.array([MIN_SPAN["tsr"] * abs(hi[0]), MIN_SPAN["pitch"],
                                   MIN_SPAN["rotor_speed"] * abs(hi[2]), MIN_SPAN["yaw"]])
    return (X[:, active] - lo[active]) / (hi - lo)[active]


def _kernel(X: np.ndarray, Z: np.ndarray, length: float) -> np.ndarray:
    d2 = np.sum((X[:, None, :] - Z[None, :, :]) ** 2, axis=-1)
    return np.exp(-0.5 * d2 / length ** 2)


def basis(cond: OperatingConditions, env: Envelope, disc: Discrepancy) -> np.ndarray:
    """φ(x) of every point: k(x, Z) K_ZZ^{-½} on a grid of inducing points over the unit box (spacing
    at most two thirds of the correlation length, fewer when the box has many axes), shape (n_points, r); φ(x)ᵀφ(x') ≈ k(x, x') [-]."""
    X = _unit(cond, env)
    d = X.shape[1]
    if d == 0:
        return np.ones((len(cond), 1))
    q = max(2, min(int(np.ceil(1.5 / disc.length)) + 1, int(np.floor(MAX_INDUCING ** (1.0 / d)))))
    Z = np.stack([a.ravel() for a in np.meshgrid(*([np.linspace(0, 1, q)] * d), indexing="ij")], axis=1)
    s, U = np.linalg.eigh(_kernel(Z, Z, disc.length))
    keep = s > 1e-8 * s.max()
    return _kernel(X, Z, disc.length) @ (U[:, keep] / np.sqrt(s[keep]))


def augment(H: np.ndarray, phi: np.ndarray, disc: Discrepancy) -> np.ndarray:
    """The whitened blocks with the discrepancy's columns: channel c's row of point j gets κ φ(x_j) in
    channel c's slot, shape (..., n_points, m, n + m·r)."""
    m, r = H.shape[-2], phi.shape[1]
    D = np.zeros(phi.shape[:1] + (m, m * r))
    for c in range(m):
        D[:, c, c * r:(c + 1) * r] = disc.scale * phi
    D = np.broadcast_to(D, H.shape[:-1] + (m * r,))
    return np.concatenate([H, D], axis=-1)
