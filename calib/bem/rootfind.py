"""Vectorized bracketed root finding for the BEM residual.

Ning's bracketing rules (Ning 2014, §2.3) give, for every section, an interval on
which the residual changes sign; a safeguarded Anderson-Björck (modified regula
falsi) iteration then converges superlinearly on all sections at once. Sections
drop out of the active set as they converge, so the cost follows the slowest ones
only on those few.

References
----------
S.A. Ning, Wind Energy 17 (2014) 1327-1345.
N. Anderson, Å. Björck, A new high order method of regula falsi type for computing
a root of an equation, BIT 13 (1973) 253-264.
"""

from __future__ import annotations

import numpy as np

EPS_PHI = 1e-6


def bracket(residual, n: int):
    """Find a sign-changing interval per section with Ning's rules.

    Parameters
    ----------
    residual : callable
        ``residual(index, phi) -> R`` for sections ``index`` (int array) at ``phi`` [rad].
    n : int
        Number of sections.

    Returns
    -------
    lo, hi, flo, fhi : ndarray, shape (n,)
    found : ndarray of bool, shape (n,)
    """
    idx = np.arange(n)
    lo = np.full(n, EPS_PHI)
    hi = np.full(n, 0.5 * np.pi)
    flo = residual(idx, lo)
    fhi = residual(idx, hi)
    found = np.isfinite(flo) & np.isfinite(fhi) & (flo * fhi <= 0)
    rest = np.flatnonzero(~found)
    if rest.size:
        fa = residual(rest, np.full(rest.size, -0.25 * np.pi))
        fb = residual(rest, np.full(rest.size, -EPS_PHI))
        neg = (fa < 0) & (fb > 0)
        i = rest[neg]
        lo[i], hi[i], flo[i], fhi[i] = -0.25 * np.pi, -EPS_PHI, fa[neg], fb[neg]
        found[i] = True
        j = rest[~neg]
        if j.size:
            fc = residual(j, np.full(j.size, np.pi - EPS_PHI))
            lo[j], hi[j], flo[j] = 0.5 * np.pi, np.pi - EPS_PHI, fhi[j]
            fhi[j] = fc
            found[j] = np.isfinite(flo[j]) & np.isfinite(fc) & (flo[j] * fc <= 0)
    return lo, hi, flo, fhi, found


def solve_brackets(residual, lo, hi, flo, fhi, active, xtol=1e-12, ftol=1e-12, max_iter=100):
    """Anderson-Björck iteration on all bracketed sections.

    Returns
    -------
    phi : ndarray, shape (n,)
        Root estimate [rad] (NaN where not ``active``).
    f : ndarray, shape (n,)
        Residual at ``phi``.
    iterations : ndarray of int, shape (n,)
    """
    n = lo.size
    a, b = lo.copy(), hi.copy()          # b holds the most recent iterate
    fa, fb = flo.copy(), fhi.copy()
    phi = np.full(n, np.nan)
    fphi = np.full(n, np.nan)
    iters = np.zeros(n, dtype=int)
    # an endpoint that is already a root
    done0 = active & ((np.abs(fa) <= ftol) | (np.abs(fb) <= ftol))
    pick_a = np.abs(fa) <= np.abs(fb)
    phi[done0] = np.where(pick_a, a, b)[done0]
    fphi[done0] = np.where(pick_a, fa, fb)[done0]
    work = np.flatnonzero(active & ~done0)
    for it in range(1, max_iter + 1):
        if work.size == 0:
            break
        aw, bw, faw, fbw = a[work], b[work], fa[work], fb[work]
        with np.errstate(all="ignore"):
            c = bw - fbw * (bw - aw) / (fbw - faw)
        lo_w, hi_w = np.minimum(aw, bw), np.maximum(aw, bw)
        bisect = ~np.isfinite(c) | (c <= lo_w) | (c >= hi_w) | (it % 8 == 0)
        c = np.where(bisect, 0.5 * (aw + bw), c)
        fc = residual(work, c)
        flip = fc * fbw < 0
        # Anderson-Björck scaling of the retained endpoint when the sign did not change
        with np.errstate(all="ignore"):
            m = 1.0 - fc / fbw
        m = np.where((m > 0) & np.isfinite(m), m, 0.5)
        new_a = np.where(flip, bw, aw)
        new_fa = np.where(flip, fbw, faw * m)
        a[work], fa[work], b[work], fb[work] = new_a, new_fa, c, fc
        iters[work] = it
        conv = (np.abs(fc) <= ftol) | (np.abs(c - new_a) <= xtol * np.maximum(1.0, np.abs(c)))
        conv &= np.isfinite(fc)
        phi[work[conv]] = c[conv]
        fphi[work[conv]] = fc[conv]
        work = work[~conv]
    if work.size:
        phi[work] = b[work]
        fphi[work] = fb[work]
    return phi, fphi, iters
