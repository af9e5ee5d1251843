"""Statistics of a steady simulation window: mean, halves (convergence) and azimuth harmonics.

Over the averaging window of N samples (equally spaced in azimuth, whole revolutions) the mean,
the means of the two halves (the convergence check), and the complex harmonic coefficients
c_n = (2/N) Σ_k x_k exp(−i n ψ_k), n = 1, 2, 3, so that x ≈ mean + Σ_n |c_n| cos(nψ + arg c_n)
with ψ the azimuth of blade 1 (0 = up) [rad].
"""

from __future__ import annotations

import numpy as np

from calib.fmu.plan import HARMONIC_ORDERS


def window_statistics(samples: np.ndarray, psi_rad: np.ndarray | None, orders=HARMONIC_ORDERS):
    """Mean, half-window means and harmonic coefficients of sampled signals.

    Parameters
    ----------
    samples : ndarray, shape (n_samples, n_signals)
        Values at the ends of the averaging steps (equally spaced in azimuth, whole
        revolutions, ``n_samples`` even).
    psi_rad : ndarray, shape (n_samples,) or None
        Azimuth of blade 1 at each sample [rad]; None: no harmonics (standstill).
    orders : sequence of int
        Harmonic orders n.

    Returns
    -------
    mean : ndarray, shape (n_signals,)
    halves : ndarray, shape (2, n_signals)
    harmonics : ndarray of complex, shape (n_signals, n_orders)
        c_n = (2/N) Σ_k x_k exp(−i n ψ_k).
    """
    x = np.asarray(samples, float)
    n = x.shape[0]
    mean = x.mean(axis=0)
    halves = np.stack([x[: n // 2].mean(axis=0), x[n // 2:].mean(axis=0)])
    if psi_rad is None:
        harmonics = np.full((x.shape[1], len(orders)), np.nan + 0j)
    else:
        basis = np.exp(-1j * np.outer(np.asarray(psi_rad, float), np.asarray(orders, float)))
        harmonics = (2.0 / n) * (x.T @ basis)
    return mean, halves, harmonics


def convergence_failures(mean: np.ndarray, halves: np.ndarray, samples: np.ndarray, rtol: float,
                         checked, names) -> list[str]:
    """Signals whose half-window means differ by more than ``rtol`` × max(|mean|, std)."""
    out = []
    std = samples.std(axis=0)
    for i in checked:
        ref = max(abs(mean[i]), std[i], 1e-300)
        diff = abs(halves[1, i] - halves[0, i])
        if not diff <= rtol * ref:
            out.append(f"{names[i]} (halves differ by {diff / ref:.2e} relative, allowed {rtol:g})")
    return out


