"""Model discrepancy: what the calibrated model still misses, carried into every prediction.

A BEM is not the rotor. Where a calibration ends with a misfit beyond the noise in a channel,
the data say the model's form is wrong there by about that much, and a prediction's interval
must say so too, more the farther it lies from the points that showed it. :func:`fit_discrepancy`
models the misfit of each such channel as a Gaussian process over the operating conditions
(Kennedy & O'Hagan 2001):

.. math::
    \\frac{z − \\hat y}{u} = δ(x) + ε, \\qquad δ \\sim GP\\bigl(0,\\ τ^2
    \\exp(−\\textstyle\\sum_d (x_d − x'_d)^2 / 2ℓ_d^2)\\bigr), \\qquad ε \\sim N(0, (σ/u)^2)

with x the tip-speed ratio, the pitch and the wind speed, each scaled by its span in the
calibration data, one length ℓ_d per condition (automatic relevance determination, Rasmussen &
Williams 2006 §5.1), and u the unit of the residuals: relative (u = |ŷ|, a misfit proportional to
the output) or the channel's own (u = the root mean square of |ŷ| over the calibration points, a
constant: a misfit of the same size in watts everywhere), whichever the residuals' marginal
likelihood prefers in channel units (the relative one carries the Jacobian Σ log|ŷ|). In relative
units the points of small output (off design) weigh most; in channel units they do not dominate
the amplitude. τ and the ℓ_d are the maximum of the marginal likelihood of the calibration
residuals (started from the best common length on :data:`LENGTHS`, then all four continuous,
with the analytic gradient; Rasmussen & Williams 2006, eq. 5.9). It is fitted after the estimate,
on its residuals ("modular" calibration, Liu, Bayarri & Berger 2009), and only for a channel whose
misfit fails the χ² test against its noise (p < :data:`SIGNIFICANCE`): where the model fits within
the noise it stays out of the way.

A prediction keeps the calibrated model's value; the discrepancy adds its mean square at the new
point, (μ(x)² + v(x)) u², to the variance: μ and v the process's conditional mean and variance given
the calibration residuals. Near the calibration points that is about the misfit seen there; far
from them μ → 0 and v → τ², the full amplitude: the interval widens to what the misfit can be
anywhere. The process is constrained by its prior amplitude only in the sense of Brynjarsdóttir &
O'Hagan (2014): it is never used to move the estimate, so it cannot absorb what the parameters
should explain.

References
----------
M.C. Kennedy, A. O'Hagan, Bayesian calibration of computer models, J. R. Stat. Soc. B 63 (2001)
425-464.
F. Liu, M.J. Bayarri, J.O. Berger, Modularization in Bayesian analysis, with emphasis on analysis
of computer models, Bayesian Analysis 4 (2009) 119-150.
J. Brynjarsdóttir, A. O'Hagan, Learning about physical parameters: the importance of model
discrepancy, Inverse Problems 30 (2014) 114007.
C.E. Rasmussen, C.K.I. Williams, Gaussian Processes for Machine Learning, MIT Press (2006), ch. 2, 5.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A channel's misfit is modelled when its χ² against the noise has a p-value below this [-].
SIGNIFICANCE = 0.01
#: Common length scales tried for the start of the fit, in units of the calibration data's span of each
#: condition [-].
LENGTHS = (0.15, 0.3, 0.6, 1.2)
#: Bounds of each condition's length scale ℓ_d in the maximization of the marginal likelihood, in units
#: of the calibration span [-]: below the shortest the process would interpolate the noise between
#: neighbouring points; above the longest it is constant over the span anyway.
LENGTH_BOUNDS = (0.05, 10.0)
#: The units the residuals may be modelled in (module notes).
UNITS = ("relative", "channel")
#: Most calibration points a channel's process is fitted on (an evenly spaced subset of them beyond
#: it): the fit costs O(n³) per likelihood evaluation, and a few hundred points already fix τ and ℓ.
MAX_POINTS = 300
#: Smallest span of a condition used to scale it: tip-speed ratio [-], pitch [deg], wind speed [m/s].
MIN_SPAN = {"tsr": 1.0, "pitch": 2.0, "wind_speed": 2.0}


@dataclass(frozen=True, eq=False)
class ChannelDiscrepancy:
    """The discrepancy process of one channel (relative units).

    Attributes
    ----------
    channel : str
    amplitude : float
        τ, the process's standard deviation [-] (a fraction of the unit u: of the output where
        ``units`` is "relative", of ``reference`` where it is "channel").
    length : float or ndarray, shape (3,)
        ℓ_d in units of each condition's calibration span [-] (one common ℓ when a float).
    p_value : float
        Of the χ² test that made the channel's misfit significant [-].
    x : ndarray, shape (n, 3)
        The calibration points' scaled conditions.
    weights, inverse : ndarray
        (τ²K + S)⁻¹ e and (τ²K + S)⁻¹ of the calibration residuals e (in units u).
    units : {"relative", "channel"}
        The unit u of the residuals (module notes).
    reference : float
        u where ``units`` is "channel" [channel unit]; unused for "relative".
    """

    channel: str
    amplitude: float
    length: float | np.ndarray
    p_value: float
    x: np.ndarray
    weights: np.ndarray
    inverse: np.ndarray
    units: str = "relative"
    reference: float = 1.0

    def unit(self, values: np.ndarray) -> np.ndarray:
        """u at predictions ``values`` [channel unit]: |ŷ| (relative) or :attr:`reference` (channel)."""
        return _unit(self.units, np.asarray(values, float), self.reference)

    def length_words(self) -> str:
        """ℓ per condition in words."""
        ell = np.broadcast_to(np.asarray(self.length, float), (3,))
        return ", ".join(f"{n} {v:.2g}" for n, v in zip(("λ", "pitch", "wind speed"), ell))

    def prior_covariance(self, x: np.ndarray) -> np.ndarray:
        """The process's prior covariance τ² k_ℓ(x, x) at scaled conditions ``x`` (n, 3) [-, in units u²]."""
        return self.amplitude ** 2 * _kernel(x, x, self.length)

    def mean_square(self, x_new: np.ndarray) -> np.ndarray:
        """μ² + v of the discrepancy at scaled conditions ``x_new`` (n, 3) [-, relative²]."""
        k = self.amplitude ** 2 * _kernel(x_new, self.x, self.length)
        mean = k @ self.weights
        var = self.amplitude ** 2 - np.einsum("ij,jk,ik->i", k, self.inverse, k)
        return mean ** 2 + np.maximum(var, 0.0)


@dataclass(frozen=True, eq=False)
class Discrepancy:
    """The discrepancy processes of the channels that misfit, and the scaling of the conditions."""

    channels: tuple
    processes: dict            # channel -> ChannelDiscrepancy (only the channels that misfit)
    offset: np.ndarray         # (3,) scaled x = (raw − offset) / span
    span: np.ndarray

    def features(self, conditions: dict, rotor_radius: float) -> np.ndarray:
        """The scaled (tip-speed ratio, pitch, wind speed) of ``conditions`` (n, 3)."""
        return (_raw_features(conditions, rotor_radius) - self.offset) / self.span

    def variance(self, conditions: dict, rotor_radius: float, values: np.ndarray) -> np.ndarray:
        """The discrepancy's mean square at ``conditions`` in channel units² (n, n_channels);
        zero for the channels that fit within their noise. ``values``: the predictions there."""
        x = self.features(conditions, rotor_radius)
        out = np.zeros(values.shape)
        for j, c in enumerate(self.channels):
            if c in self.processes:
                q = self.processes[c]
                out[:, j] = q.mean_square(x) * q.unit(values[:, j]) ** 2
        return out

    def words(self) -> str:
        """The channels that carry a discrepancy, with amplitude and length scale, in words."""
        if not self.processes:
            return "no channel misfits beyond its noise: no model-discrepancy term"
        return "model discrepancy (Kennedy–O'Hagan, fitted to the calibration residuals): " + "; ".join(
            f"{c} τ = {_amplitude_words(q)} (lengths {q.length_words()} of the calibration span, misfit "
            f"p = {q.p_value:.2g})" for c, q in self.processes.items())


def _amplitude_words(q: ChannelDiscrepancy) -> str:
    if q.units == "relative":
        return f"{100 * q.amplitude:.3g} % of the output"
    return f"{q.amplitude * q.reference:.3g} in channel units ({100 * q.amplitude:.3g} % of the rms output)"


def _raw_features(conditions: dict, rotor_radius: float | None) -> np.ndarray:
    """(tip-speed ratio, pitch [deg], wind speed [m/s]); without a rotor radius, Ω/V [rad/m] for the first."""
    v = np.asarray(conditions["wind_speed"], float)
    rpm = np.asarray(conditions["rotor_speed"], float)
    tsr = rpm * np.pi / 30.0 * (rotor_radius or 1.0) / v
    return np.column_stack([tsr, np.asarray(conditions["pitch"], float) * np.ones_like(v), v])


def _kernel(a: np.ndarray, b: np.ndarray, length) -> np.ndarray:
    """exp(−Σ_d (a_d − b_d)² / 2ℓ_d²) between the rows of ``a`` and ``b``; ``length`` a float or one per column."""
    d = (a[:, None, :] - b[None, :, :]) / np.asarray(length, float)
    return np.exp(-0.5 * (d ** 2).sum(axis=-1))


def _nll_grad(theta: np.ndarray, d2: np.ndarray, e: np.ndarray, s2: np.ndarray, grad: bool = True,
              unit_kernel: np.ndarray | None = None):
    """Negative log marginal likelihood of e ~ N(0, τ²K + diag(s2)) and (``grad``) its gradient in
    θ = (log τ, log ℓ_1..log ℓ_D) (Rasmussen & Williams 2006, eqs. 5.8-5.9); ``d2`` (D, n, n) the squared
    differences per condition; ``unit_kernel``: K at θ's lengths when already known (the likelihood alone)."""
    tau2, ell = np.exp(2.0 * theta[0]), np.exp(theta[1:])
    if not grad and unit_kernel is not None:
        K = tau2 * unit_kernel
    else:
        scaled = d2 / ell[:, None, None] ** 2
        K = tau2 * np.exp(-0.5 * scaled.sum(axis=0))
    L = np.linalg.cholesky(K + np.diag(s2))
    if not grad:
        w = np.linalg.solve(L, e)
        return 0.5 * float(w @ w) + float(np.log(np.diag(L)).sum())
    Li = np.linalg.inv(L)
    Ainv = Li.T @ Li
    alpha = Ainv @ e
    nll = 0.5 * float(e @ alpha) + float(np.log(np.diag(L)).sum())
    WK = (Ainv - np.outer(alpha, alpha)) * K
    g = np.empty(theta.size)
    g[0] = float(WK.sum())                                           # ½ tr(W ∂A/∂log τ), ∂A = 2K
    g[1:] = 0.5 * np.einsum("ij,dij->d", WK, scaled)                 # ∂A/∂log ℓ_d = K (Δ_d/ℓ_d)²
    return nll, g


def _fit_process(x: np.ndarray, e: np.ndarray, s2: np.ndarray) -> tuple[float, float, np.ndarray]:
    """(nll, τ, ℓ (D,)) of the largest marginal likelihood of e ~ N(0, τ²K_ℓ + diag(s2)): the best common
    ℓ on :data:`LENGTHS` (τ by a bounded scalar search), then τ and each ℓ_d by L-BFGS-B."""
    from scipy.optimize import minimize, minimize_scalar

    d2 = np.moveaxis((x[:, None, :] - x[None, :, :]) ** 2, -1, 0)
    top = np.log(max(np.sqrt(np.mean(e ** 2)) * 10.0, 1e-6))
    best = None
    for length in LENGTHS:
        th = np.log(np.full(x.shape[1], length))
        ell = np.exp(th)
        unit = np.exp(-0.5 * (d2 / ell[:, None, None] ** 2).sum(axis=0))      # as _nll_grad forms it
        opt = minimize_scalar(lambda lt, th=th, unit=unit: _nll_grad(np.concatenate([[lt], th]), d2, e, s2,
                                                                     grad=False, unit_kernel=unit),
                              bounds=(top - 12.0, top), method="bounded", options={"xatol": 1e-3})
        if best is None or opt.fun < best[0]:
            best = (float(opt.fun), np.concatenate([[opt.x], th]))
    bounds = [(top - 12.0, top)] + [tuple(np.log(LENGTH_BOUNDS))] * x.shape[1]
    try:
        opt = minimize(_nll_grad, best[1], args=(d2, e, s2), jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": 60})
        if np.isfinite(opt.fun) and opt.fun <= best[0]:
            best = (float(opt.fun), opt.x)
    except np.linalg.LinAlgError:
        pass                                   # keep the common length's optimum
    return best[0], float(np.exp(best[1][0])), np.clip(np.exp(best[1][1:]), *LENGTH_BOUNDS)


def _unit(units: str, y: np.ndarray, reference: float) -> np.ndarray:
    """The unit u of the residuals at predictions ``y`` [channel unit]: |ŷ| (``"relative"``) or ``reference``."""
    return np.abs(y) if units == "relative" else np.full(y.shape, float(reference))


def _fit_channel(channel: str, x: np.ndarray, r: np.ndarray, s: np.ndarray, y: np.ndarray,
                 p_value: float) -> ChannelDiscrepancy:
    """The process of residuals ``r`` = z − ŷ with noise 1-σ ``s`` [channel units] at predictions ``y``, in
    the units (:data:`UNITS`) of the larger marginal likelihood of r (module notes)."""
    ref = float(np.sqrt(np.mean(y ** 2)))
    fits = {}
    for units in UNITS:
        u = _unit(units, y, ref)
        nll, tau, ell = _fit_process(x, r / u, (s / u) ** 2)
        fits[units] = (nll + float(np.log(u).sum()), tau, ell)       # in channel units: + Σ log u
    units = min(fits, key=lambda k: fits[k][0])
    _, tau, ell = fits[units]
    u = _unit(units, y, ref)
    inverse = np.linalg.inv(tau ** 2 * _kernel(x, x, ell) + np.diag((s / u) ** 2))
    return ChannelDiscrepancy(channel, tau, ell, p_value, x, inverse @ (r / u), inverse, units, ref)


def fit_discrepancy(result) -> Discrepancy:
    """The discrepancy of a :class:`~calib.calibration.result.CalibrationResult` (see the module notes).

    Its channels' residuals at the converged points (at most :data:`MAX_POINTS` of them, evenly
    spaced), relative or in channel units (module notes); a channel gets a process when its χ² against the noise
    (over every converged point) fails at :data:`SIGNIFICANCE` (χ² with one
    degree of freedom per point: the test is conservative, the estimate's own parameters take
    some of the misfit).
    """
    from scipy import stats

    fit = result.fit
    radius = result.provenance.rotor_radius
    raw = _raw_features(result.conditions, radius)
    ok = fit.status_after == 0
    offset = raw[ok].min(axis=0) if ok.any() else np.zeros(3)
    floor = [MIN_SPAN["tsr"] if radius else 1e-9, MIN_SPAN["pitch"], MIN_SPAN["wind_speed"]]
    span = np.maximum(np.ptp(raw[ok], axis=0) if ok.any() else np.ones(3), floor)
    x_all = (raw - offset) / span
    processes = {}
    for j, c in enumerate(result.channels):
        y, z, s = fit.model_after[:, j], fit.measured[:, j], fit.sigma[:, j]
        use = ok & np.isfinite(y) & np.isfinite(z) & (np.abs(y) > 0) & (s > 0)
        if use.sum() < 3:
            continue
        chi2 = float(np.sum(((z - y) / s)[use] ** 2))
        p = float(stats.chi2.sf(chi2, int(use.sum())))
        if p >= SIGNIFICANCE:
            continue
        rows = np.flatnonzero(use)
        if rows.size > MAX_POINTS:
            rows = rows[np.round(np.linspace(0, rows.size - 1, MAX_POINTS)).astype(int)]
        processes[c] = _fit_channel(c, x_all[rows], (z - y)[rows], s[rows], y[rows], p)
    return Discrepancy(tuple(result.channels), processes, offset, span)
