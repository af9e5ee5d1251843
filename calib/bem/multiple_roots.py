"""Several roots of Ning's residual in one bracket: detection and the choice among them.

Ning's brackets guarantee a sign change, not a single root. Near stall the residual can
cross zero several times inside the bracket (NREL Phase VI at 20 m/s, r/R = 0.994: roots
at α ≈ 17.5, 19.5 and 20.0 deg), and which one a bracketing iteration lands on is an
accident of the iteration. This module finds the other roots near the one found and
applies one documented rule.

Where several roots come from
-----------------------------
Along φ the slope of the residual splits into a smooth part and the polar's slopes:

.. math::
    \\frac{dR}{dφ} = \\underbrace{\\frac{∂R}{∂φ}}_{D_0}
                   + \\underbrace{\\frac{∂R}{∂C_L}}_{D_L} \\frac{dC_L}{dα}
                   + \\underbrace{\\frac{∂R}{∂C_D}}_{D_D} \\frac{dC_D}{dα}

D_0, D_L, D_D (trigonometry, loss factor, solidity) change slowly with φ; the polar
slopes change on the scale of the airfoil table. A single root has R' > 0; several roots
need R' < 0 between them, which (D_L > 0) takes a lift slope steep and negative enough to
overcome D_0: a stall drop of the polar. That is the screen. Sections without a negative
lift slope within ``WINDOW_DEG`` of the root's α are not searched; for the others D_0, D_L,
D_D are evaluated at the root (one-sided differences) and, with the extreme polar slopes
within the window, the section is searched when
``D_0 + min(D_L C_L') + min(D_D C_D') < SCREEN_MARGIN·D_0``, i.e. when the polar could
remove more than half of the smooth slope somewhere in the window (the margin covers the
variation of D_0, D_L, D_D across the window). Over about 290 000 converged sections of
λ–pitch sweeps of the NREL 5-MW, IEA 3.4-MW, IEA 15-MW and Phase VI rotors and of CCBlade's
IEA 3.4-MW table points, this slope test never selected a section without a negative lift
slope in its window.

Search
------
A screened section's residual is sampled every ``SCAN_STEP_DEG`` on φ* ± ``WINDOW_DEG``,
half a step off the root, and the sign changes are counted. A pair of roots between two
samples shows as a sampled local extremum of the wrong sign (a maximum below zero, a
minimum above); those are searched on nested sub-grids (``REFINE_LEVELS`` ×
``REFINE_POINTS``). Not seen: pairs hidden between two samples without such an extremum,
roots farther than ``WINDOW_DEG`` from every root visited, and several roots caused by
anything but a negative lift slope. A brute-force scan (8000 points per bracket, one
sector) of λ–pitch sweeps of the same rotors, of CCBlade's IEA 3.4-MW table points and of
Phase VI sequence H found 50 sections with several roots; the search found all of them and
kept the smallest root in each.

Rule
----
The root of smallest |φ| is kept (in the windmill bracket: the smallest inflow angle, i.e.
the smallest α, the least stalled flow). It is the root that continues the attached-flow
solution as the wind speed rises from below (the others appear in pairs, above it, when
the stall drop folds the residual), it crosses zero upward like the unique root of an
attached section, and it does not depend on the iteration. It is also the root CCBlade's
Brent solve on [ε, π/2] returns at Phase VI 20 m/s. The search descends: after moving to a
lower root it searches around that one again.

References
----------
S.A. Ning, A simple solution method for the blade element momentum equations with
guaranteed convergence, Wind Energy 17 (2014) 1327-1345 (§2.3: the bracket holds at least
one root; CCBlade smooths its polars "to prevent spurious multiple solutions").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import maximum_filter1d, minimum_filter1d

from calib.bem.rootfind import solve_brackets

WINDOW_DEG = 5.0
"""Half width of the searched window around a root [deg of φ] (the Phase VI and IEA 3.4-MW
clusters span up to 2.5 deg)."""

SCAN_STEP_DEG = 0.5
"""Spacing of the residual samples in the window [deg of φ]."""

SCREEN_MARGIN = 0.5
"""Search a section when the polar slopes could bring dR/dφ below this fraction of D_0 [-]."""

MAX_DESCENT = 10
"""Largest number of successive moves to a lower root."""

REFINE_LEVELS, REFINE_POINTS = 2, 16
"""Nested sub-grids searching a sampled extremum for a hidden pair of roots (resolution
2 / 17² ≈ 0.007 of a step)."""


@dataclass(frozen=True, eq=False)
class SlopeEnvelope:
    """Extreme polar slopes within ± a window around every α node of every station.

    Attributes
    ----------
    cl_min, cl_max, cd_min, cd_max : ndarray, shape (n_stations, n_grid)
        Smallest / largest dC_L/dα, dC_D/dα within the window [1/deg] (of the polars after
        the effect chain's polar stage, corrections included).
    step_deg : float
        Node spacing of the polar grid [deg].
    first_node : int
        Grid node of the tables' first column (a sub-range of the -180..180 deg grid).
    """

    cl_min: np.ndarray
    cl_max: np.ndarray
    cd_min: np.ndarray
    cd_max: np.ndarray
    step_deg: float
    first_node: int = 0

    @classmethod
    def build(cls, cl_slopes, cd_slopes, step_deg: float, half_width_deg: float = WINDOW_DEG,
              first_node: int | None = None) -> "SlopeEnvelope":
        """From slope tables on a uniform α grid: the whole periodic grid, or a sub-range.

        Parameters
        ----------
        cl_slopes, cd_slopes : ndarray, shape (n_stations, n_grid)
            dC_L/dα, dC_D/dα at the grid nodes [1/deg] (e.g. ``SectionPolars.cl_slopes``, or
            the polars after an effect chain's polar stage).
        step_deg : float
            Node spacing [deg].
        half_width_deg : float
            Half width of the window [deg].
        first_node : int, optional
            The tables cover nodes ``first_node ...`` of the -180..180 deg grid (not periodic:
            the envelope holds on nodes at least a window inside the sub-range). None: the
            whole periodic grid.
        """
        size = 2 * int(np.ceil(half_width_deg / step_deg)) + 1
        mode = "wrap" if first_node is None else "nearest"
        env = [f(s, size, axis=1, mode=mode) for s in (cl_slopes, cd_slopes)
               for f in (minimum_filter1d, maximum_filter1d)]
        return cls(*env, step_deg=step_deg, first_node=int(first_node or 0))

    def union(self, other: "SlopeEnvelope") -> "SlopeEnvelope":
        """The envelope covering both (smallest minima, largest maxima)."""
        return SlopeEnvelope(np.minimum(self.cl_min, other.cl_min), np.maximum(self.cl_max, other.cl_max),
                             np.minimum(self.cd_min, other.cd_min), np.maximum(self.cd_max, other.cd_max),
                             self.step_deg, self.first_node)

    def at(self, alpha_deg, station):
        """(cl_min, cl_max, cd_min, cd_max) [1/deg] at the nearest node of each (α, station)."""
        n_grid = self.cl_min.shape[1]
        node = np.rint(np.mod(np.asarray(alpha_deg, float) + 180.0, 360.0) / self.step_deg).astype(np.intp)
        node = np.clip(node - self.first_node, 0, n_grid - 1)
        return tuple(e[station, node] for e in (self.cl_min, self.cl_max, self.cd_min, self.cd_max))


def needs_search(d0, d_cl, d_cd, envelope_values, margin: float = SCREEN_MARGIN) -> np.ndarray:
    """Sections whose residual may turn back within the window (see the module notes).

    Parameters
    ----------
    d0 : ndarray, shape (n,)
        ∂R/∂φ at fixed C_L, C_D [1/rad].
    d_cl, d_cd : ndarray, shape (n,)
        ∂R/∂C_L, ∂R/∂C_D [-].
    envelope_values : tuple of ndarray
        ``SlopeEnvelope.at(...)``: extreme slopes [1/deg].
    """
    per_rad = 180.0 / np.pi
    cl_min, cl_max, cd_min, cd_max = (v * per_rad for v in envelope_values)
    worst = d0 + np.minimum(d_cl * cl_min, d_cl * cl_max) + np.minimum(d_cd * cd_min, d_cd * cd_max)
    return ~(worst >= margin * np.abs(d0)) | ~(d0 > 0)


def scan_window(residual, index, center, lo, hi, step, n_half):
    """Sign changes of the residual on a window around known roots.

    Samples φ_j = center + (j − n_half + ½) step, j = 0 … 2 n_half − 1 (none on the root),
    kept strictly inside (lo, hi). A pair of roots closer than one step hides between two
    samples of the same sign as a local extremum of that sign (a local maximum of negative
    samples, a local minimum of positive ones): each such extremum is searched on nested
    sub-grids of its two neighbouring cells and added to the samples.

    Parameters
    ----------
    residual : callable
        ``residual(index, phi) -> R``.
    index : ndarray of int, shape (n,)
        Sections.
    center, lo, hi : ndarray, shape (n,)
        Known root and bracket [rad].
    step : float
        Sample spacing [rad].
    n_half : int

    Returns
    -------
    n_roots : ndarray of int, shape (n,)
        Roots seen: sign changes between consecutive samples, plus 2 when the root's own cell
        shows none (an even number >= 2 of roots share it).
    cell_lo, cell_hi, f_lo, f_hi : ndarray, shape (n,)
        The sign-changing cell of smallest |φ| and its residuals (NaN where there is none).
    lower : ndarray of bool, shape (n,)
        That cell lies nearer φ = 0 than the root's own cell.
    """
    n = index.size
    offsets = (np.arange(2 * n_half) - n_half + 0.5) * step
    phi = center[:, None] + offsets[None, :]
    keep = (phi > lo[:, None]) & (phi < hi[:, None])
    f = np.full(phi.shape, np.nan)
    rows = np.broadcast_to(index[:, None], phi.shape)
    f[keep] = residual(rows[keep], phi[keep])
    valid = keep & np.isfinite(f)
    phi_x, f_x = _hidden_extrema(residual, index, phi, f, valid)

    # all samples of a section in order of φ (invalid ones last)
    phi_all = np.concatenate([phi, phi_x], axis=1)
    f_all = np.concatenate([f, f_x], axis=1)
    ok = np.isfinite(f_all) & np.isfinite(phi_all)
    order = np.argsort(np.where(ok, phi_all, np.inf), axis=1, kind="stable")
    phi_all, f_all, ok = (np.take_along_axis(a, order, axis=1) for a in (phi_all, f_all, ok))
    pos = f_all > 0
    change = ok[:, 1:] & ok[:, :-1] & (pos[:, 1:] != pos[:, :-1])
    r = np.arange(n)
    own = (ok & (phi_all < center[:, None])).sum(axis=1) - 1        # cell holding the root
    own_ok = (own >= 0) & (own + 1 < ok.sum(axis=1))
    own_c = np.clip(own, 0, change.shape[1] - 1)
    hidden = own_ok & ~change[r, own_c]
    n_roots = change.sum(axis=1) + 2 * hidden
    cells = np.arange(change.shape[1])
    toward_zero = center >= 0            # windmill brackets: smallest φ; brake bracket: largest φ
    first = np.where(change, cells, change.shape[1]).min(axis=1)
    last = np.where(change, cells, -1).max(axis=1)
    pick = np.where(toward_zero, first, last)
    has = change.any(axis=1)
    lower = has & np.where(toward_zero, pick < np.where(own_ok, own, -1),
                           pick > np.where(own_ok, own, change.shape[1]))
    pick = np.clip(pick, 0, change.shape[1] - 1)
    nan = np.where(has, 1.0, np.nan)
    return (n_roots, phi_all[r, pick] * nan, phi_all[r, pick + 1] * nan, f_all[r, pick] * nan,
            f_all[r, pick + 1] * nan, lower)


def _hidden_extrema(residual, index, phi, f, valid, levels: int = REFINE_LEVELS, points: int = REFINE_POINTS):
    """Extrema of the residual that change sign between samples of one sign.

    A sample j whose residual is a local maximum below zero (minimum above zero) of its
    neighbours may hide a pair of roots in [φ_{j-1}, φ_{j+1}]: that interval is sampled on
    ``points`` sub-points, then ``points`` sub-points around the most extreme one, ``levels``
    times (all candidates in one vectorized call per level).

    Returns arrays shaped like ``phi``: at column j the most extreme sub-point found around
    sample j when its residual has the other sign than sample j, NaN elsewhere.
    """
    out_phi = np.full(phi.shape, np.nan)
    out_f = np.full(phi.shape, np.nan)
    if phi.shape[1] < 3:
        return out_phi, out_f
    fl, fc, fr = f[:, :-2], f[:, 1:-1], f[:, 2:]
    both = valid[:, :-2] & valid[:, 1:-1] & valid[:, 2:]
    with np.errstate(invalid="ignore"):
        bump = both & (fc < 0) & (fc >= fl) & (fc >= fr)     # a maximum below zero
        dip = both & (fc > 0) & (fc <= fl) & (fc <= fr)      # a minimum above zero
    rr, jj = np.nonzero(bump | dip)
    if rr.size == 0:
        return out_phi, out_f
    jj = jj + 1
    sign = np.where(dip[rr, jj - 1], 1.0, -1.0)            # look for the smallest sign * R
    sec = index[rr]
    a, b = phi[rr, jj - 1], phi[rr, jj + 1]
    best, g_best = phi[rr, jj], sign * f[rr, jj]
    t = np.linspace(0.0, 1.0, points + 2)[1:-1]
    for _ in range(levels):
        x = a[:, None] + (b - a)[:, None] * t[None, :]
        g = sign[:, None] * residual(np.repeat(sec, points), x.reshape(-1)).reshape(x.shape)
        g = np.where(np.isfinite(g), g, np.inf)
        k = g.argmin(axis=1)
        r = np.arange(rr.size)
        better = g[r, k] < g_best
        best, g_best = np.where(better, x[r, k], best), np.where(better, g[r, k], g_best)
        width = (b - a) / (points + 1)
        a, b = best - width, best + width
    f_best = sign * g_best
    flipped = np.isfinite(f_best) & ((f_best > 0) != (f[rr, jj] > 0))
    out_phi[rr[flipped], jj[flipped]] = best[flipped]
    out_f[rr[flipped], jj[flipped]] = f_best[flipped]
    return out_phi, out_f


def lowest_roots(residual, phi, fphi, lo, hi, candidates, step, half_width, tol, max_iter=100,
                 max_descent: int = MAX_DESCENT):
    """Search the candidate sections for other roots and keep the one of smallest |φ|.

    Parameters
    ----------
    residual : callable
        ``residual(index, phi) -> R`` for sections ``index``.
    phi, fphi : ndarray, shape (n,)
        Converged roots and residuals [rad], [-].
    lo, hi : ndarray, shape (n,)
        Ning's bracket of each section [rad].
    candidates : ndarray of bool, shape (n,)
        Sections to search (converged and passed by :func:`needs_search`).
    step, half_width : float
        Sample spacing and half width of the window [rad].
    tol : float
        |R| below which a root counts as converged [-]; a lower root that does not converge
        leaves the section at its previous root (still counted as several roots).

    Returns
    -------
    phi, fphi : ndarray, shape (n,)
        The kept roots.
    n_roots : ndarray of int, shape (n,)
        Most roots seen in one window (1 where not searched).
    """
    phi, fphi = phi.copy(), fphi.copy()
    n_roots = np.ones(phi.size, dtype=int)
    n_half = max(1, int(np.ceil(half_width / step)))
    work = np.flatnonzero(candidates)
    for _ in range(max_descent + 1):
        if work.size == 0:
            break
        count, c_lo, c_hi, f_lo, f_hi, lower = scan_window(residual, work, phi[work], lo[work], hi[work],
                                                           step, n_half)
        n_roots[work] = np.maximum(n_roots[work], count)
        move = np.flatnonzero(lower)
        if move.size == 0:
            break
        new_phi, new_f, _ = solve_brackets(lambda i, x: residual(work[move][i], x), c_lo[move], c_hi[move],
                                           f_lo[move], f_hi[move], np.ones(move.size, bool),
                                           max_iter=max_iter)
        ok = np.isfinite(new_f) & (np.abs(new_f) <= tol)
        phi[work[move[ok]]], fphi[work[move[ok]]] = new_phi[ok], new_f[ok]
        work = work[move[ok]]
    return phi, fphi, n_roots
