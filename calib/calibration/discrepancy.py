"""Model discrepancy: what the calibrated model still misses, carried into every prediction.

A BEM is not the rotor. Where a calibration ends with a misfit beyond the noise in a channel,
the data say the model's form is wrong there by about that much, and a prediction's interval
must say so too, more the farther it lies from the points that showed it. :func:`fit_discrepancy`
models the misfit of each such channel as a Gaussian process over the operating conditions, in
relative units (Kennedy & O'Hagan 2001):

.. math::
    \\frac{z − \\hat y}{|\\hat y|} = δ(x) + ε, \\qquad δ \\sim GP\\bigl(0,\\ τ^2
    \\exp(−|x − x'|^2 / 2ℓ^2)\\bigr), \\qquad ε \\sim N(0, (σ/|\\hat y|)^2)

with x the tip-speed ratio, the pitch and the wind speed, each scaled by its span in the
calibration data, and τ, ℓ the maximum of the marginal likelihood (ℓ on :data:`LENGTHS`, τ
continuous). It is fitted after the estimate, on its residuals ("modular" calibration, Liu,
Bayarri & Berger 2009), and only for a channel whose misfit fails the χ² test against its noise
(p < :data:`SIGNIFICANCE`): where the model fits within the noise it stays out of the way.

A prediction keeps the calibrated model's value; the discrepancy adds its mean square at the new
point, μ(x)² + v(x), to the variance: μ and v the process's conditional mean and variance given
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
#: Length scales tried, in units of the calibration data's span of each condition [-].
LENGTHS = (0.15, 0.3, 0.6, 1.2)
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
        τ, the process's standard deviation [-] (a fraction of the output).
    length : float
        ℓ in units of each condition's calibration span [-].
    p_value : float
        Of the χ² test that made the channel's misfit significant [-].
    x : ndarray, shape (n, 3)
        The calibration points' scaled conditions.
    weights, inverse : ndarray
        (τ²K + S)⁻¹ e and (τ²K + S)⁻¹ of the calibration residuals e.
    """

    channel: str
    amplitude: float
    length: float
    p_value: float
    x: np.ndarray
    weights: np.ndarray
    inverse: np.ndarray

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
                out[:, j] = self.processes[c].mean_square(x) * values[:, j] ** 2
        return out

    def words(self) -> str:
        """The channels that carry a discrepancy, with amplitude and length scale, in words."""
        if not self.processes:
            return "no channel misfits beyond its noise: no model-discrepancy term"
        return "model discrepancy (Kennedy–O'Hagan, fitted to the calibration residuals): " + "; ".join(
            f"{c} τ = {100 * q.amplitude:.3g} % (length {q.length:g} of the calibration span, misfit "
            f"p = {q.p_value:.2g})" for c, q in self.processes.items())


def _raw_features(conditions: dict, rotor_radius: float | None) -> np.ndarray:
    """(tip-speed ratio, pitch [deg], wind speed [m/s]); without a rotor radius, Ω/V [rad/m] for the first."""
    v = np.asarray(conditions["wind_speed"], float)
    rpm = np.asarray(conditions["rotor_speed"], float)
    tsr = rpm * np.pi / 30.0 * (rotor_radius or 1.0) / v
    return np.column_stack([tsr, np.asarray(conditions["pitch"], float) * np.ones_like(v), v])


def _kernel(a: np.ndarray, b: np.ndarray, length: float) -> np.ndarray:
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=-1)
    return np.exp(-0.5 * d2 / length ** 2)


def _fit_channel(channel: str, x: np.ndarray, e: np.ndarray, s2: np.ndarray, p_value: float) -> ChannelDiscrepancy:
    """τ and ℓ of the largest marginal likelihood of e ~ N(0, τ²K_ℓ + diag(s2))."""
    from scipy.optimize import minimize_scalar

    best = None
    top = np.log(max(np.sqrt(np.mean(e ** 2)) * 10.0, 1e-6))
    for length in LENGTHS:
        K = _kernel(x, x, length)

        def nll(log_tau, K=K):
            A = np.exp(2 * log_tau) * K + np.diag(s2)
            L = np.linalg.cholesky(A)
            w = np.linalg.solve(L, e)
            return 0.5 * w @ w + np.log(np.diag(L)).sum()

        opt = minimize_scalar(nll, bounds=(top - 12.0, top), method="bounded")
        if best is None or opt.fun < best[0]:
            best = (opt.fun, float(np.exp(opt.x)), length)
    _, tau, length = best
    inverse = np.linalg.inv(tau ** 2 * _kernel(x, x, length) + np.diag(s2))
    return ChannelDiscrepancy(channel, tau, length, p_value, x, inverse @ e, inverse)


def fit_discrepancy(result) -> Discrepancy:
    """The discrepancy of a :class:`~calib.calibration.result.CalibrationResult` (see the module notes).

    Its channels' residuals at the converged points (at most :data:`MAX_POINTS` of them, evenly
    spaced), relative to the calibrated model; a channel gets a process when its χ² against the noise
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
        e = (z - y)[rows] / np.abs(y[rows])
        processes[c] = _fit_channel(c, x_all[rows], e, (s[rows] / np.abs(y[rows])) ** 2, p)
    return Discrepancy(tuple(result.channels), processes, offset, span)
