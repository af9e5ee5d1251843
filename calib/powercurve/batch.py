"""Many parameter vectors in one BEM solve: the posterior draws of a power curve, batched.

:func:`batched_solver` returns ``solve(draw, conditions) -> BemResult`` where ``draw`` is an integer
array giving, per operating point, the row of a matrix of parameter vectors (one per posterior
draw) the point is solved at. It runs :func:`calib.bem.solver.solve_bem` once on an effect chain
whose effects read their parameters per point instead of once per call: every draw's region-2
λ search, region-2 bins and region-3 pitch iterations stack into a few large vectorized solves
instead of a few small solves per draw (the solver's cost per call is mostly fixed below ~100
points).

Supported chains: the correction field (:class:`calib.effects.correction_field.CorrectionFieldEffect`,
per point ΔC_L, ΔC_D = Σ N_i(α) H_j(η) p_ij, Bottasso et al. 2014) and conditions-stage effects
that act elementwise on the inflow and do not read the thrust (the nuisance ``pitch_offset`` and
``wind_scale``). :func:`batchable` says why another chain is not supported; the caller then
solves the draws one by one.

The polar stage sees its sections through the solver's section context; the point each section
belongs to is recovered from the context's layout (points × sectors × interior stations, every
interior station active: vx > 0). Where the layout is not that of the batch (the solver's table
of polar slopes for the multiple-root screen, tabulated per station and α node, not per point)
the effect returns, per row, the correction of the draw with the most negative dC_L/dα (the
screen searches for roots where the lift slope is negative; the most negative slope over the
draws searches at least where any draw would). The search itself keeps the root of smallest |φ|,
so a wider screen changes no result where a section has one root.
"""

from __future__ import annotations

import numpy as np

from calib.bem import dual as dl
from calib.bem.chain import EffectChain
from calib.bem.solver import interior_stations, solve_bem
from calib.effects.correction_field import CorrectionFieldEffect, floor_drag

__all__ = ["batchable", "batched_solver"]


class BatchLayoutError(RuntimeError):
    """The sections handed to a batched effect are not laid out as expected (a solver change)."""


def batchable(model) -> str:
    """Why ``model`` cannot be solved with per-point parameters ('' when it can)."""
    from calib.models.bem_model import BemModel

    if not isinstance(model, BemModel):
        return f"the model is a {type(model).__name__}, not the native BEM (its own solve is called per draw)"
    for e in model.chain.effects:
        if isinstance(e, CorrectionFieldEffect):
            continue
        if e.stage == "conditions" and not e.reads_thrust:
            continue
        return f"the effect {e.name!r} (stage {e.stage}) has no per-point parameter path"
    return ""


class _Batch:
    """The parameter matrix and, for the current solve, the draw of every point."""

    def __init__(self, P, n_interior: int):
        self.P = np.asarray(P, float)
        self.n_interior = int(n_interior)
        self.draw = np.zeros(0, int)
        self._layout = {}

    def section_draws(self, ctx):
        """Draw index of every section of ``ctx`` (None when ``ctx`` is not laid out as the batch)."""
        idx = None
        root = ctx
        while getattr(root, "_parent", None) is not None:
            i = root._idx
            if isinstance(i, slice) or np.asarray(i).dtype == bool:
                i = np.arange(np.size(root._parent.station))[i]
            i = np.asarray(i, int)
            idx = i if idx is None else i[idx]
            root = root._parent
        key = id(root)
        if key not in self._layout:
            self._layout[key] = self._point_of_section(root)
        pos = self._layout[key]
        if pos is None:
            return None
        return self.draw[pos if idx is None else pos[idx]]

    def _point_of_section(self, root):
        station = np.asarray(root.station)
        n_pts, m = self.draw.size, self.n_interior
        if n_pts == 0 or m == 0 or station.size % (n_pts * m):
            return None
        rows = station.reshape(-1, m)
        if not np.all(rows == rows[0]) or np.any(np.diff(rows[0]) <= 0):
            return None
        n_sec = rows.shape[0] // n_pts
        return np.repeat(np.arange(n_pts), n_sec * m)


class _BatchedCorrectionField:
    """The correction field with its nodal values read per section (the section's draw)."""

    n_probes = 0
    reads_thrust = False
    uses_flow = False

    def __init__(self, effect: CorrectionFieldEffect, offset: int, batch: _Batch):
        self.effect, self.offset, self.batch = effect, offset, batch
        self.name, self.stage, self.order = effect.name, effect.stage, effect.order
        self.grid = effect.grid

    def parameters(self):
        return self.effect.parameters()

    @property
    def _block(self):
        if getattr(self, "_contiguous", None) is None or self._contiguous[0] is not self.batch.P:
            self._contiguous = (self.batch.P, np.ascontiguousarray(
                self.batch.P[:, self.offset:self.offset + self.grid.n_params]))
        return self._contiguous[1]

    def apply(self, theta, state, ctx, probes=None):
        g = self.grid
        a = state.alpha_deg
        index, value, dvalue = (np.asarray(x) for x in g.basis(dl.value(a), ctx.eta))
        draws = self.batch.section_draws(ctx)
        if draws is None:
            if not isinstance(a, dl.Dual):
                raise BatchLayoutError("the polar stage was called on sections not laid out as the batch")
            # the slope table of the multiple-root screen: per row the draw of most negative dC_L/dα
            lift_all = self.batch.P[:, self.offset:self.offset + g.n_lift]           # (D, n_lift)
            best, draws = np.full(index.shape[0], np.inf), np.zeros(index.shape[0], int)
            for start in range(0, lift_all.shape[0], 128):                          # bounded memory
                s = np.einsum("nc,dnc->dn", dvalue, lift_all[start:start + 128][:, index])
                k = np.argmin(s, axis=0)
                smin = s[k, np.arange(s.shape[1])]
                better = smin < best
                best, draws = np.where(better, smin, best), np.where(better, k + start, draws)
        flat = self._block.ravel()
        at = draws[:, None] * self.grid.n_params + index                              # (n, 4) into flat
        lift, drag = flat.take(at), flat.take(at + g.n_lift)                         # nodal values
        dcl, dcd = np.einsum("ij,ij->i", value, lift), np.einsum("ij,ij->i", value, drag)
        if isinstance(a, dl.Dual):
            scl, scd = np.einsum("ij,ij->i", dvalue, lift), np.einsum("ij,ij->i", dvalue, drag)
            dcl, dcd = dl.Dual(dcl, scl[:, None] * a.d), dl.Dual(dcd, scd[:, None] * a.d)
        cl, cd = state.cl + dcl, state.cd + dcd
        return state.replace(cl=cl, cd=floor_drag(cd, state.cd, g.cd_floor))


class _BatchedConditions:
    """A conditions-stage effect with its parameters read per point (elementwise on the inflow)."""

    n_probes = 0
    reads_thrust = False
    uses_flow = False

    def __init__(self, effect, offset: int, batch: _Batch):
        self.effect, self.offset, self.batch = effect, offset, batch
        self.name, self.stage, self.order = effect.name, effect.stage, effect.order
        self._n = len(effect.parameters())

    def parameters(self):
        return self.effect.parameters()

    def apply(self, theta, inflow, ctx):
        d = self.batch.draw
        if np.shape(inflow.wind_speed) != d.shape:
            raise BatchLayoutError("the conditions stage was called on points not laid out as the batch")
        return self.effect.apply(tuple(self.batch.P[d, self.offset + j] for j in range(self._n)), inflow, ctx)


def batched_solver(model, P):
    """``solve(draw, conditions)``: the BEM of ``model`` with per-point parameters ``P[draw]``.

    Parameters
    ----------
    model : BemModel
        With a chain :func:`batchable` accepts.
    P : ndarray, shape (n_draws, n_params)
        Parameter vectors (in the model's order and units).

    Returns
    -------
    callable
        ``solve(draw, conditions) -> BemResult`` with ``draw`` an int array, shape (n_points,).
    """
    why = batchable(model)
    if why:
        raise ValueError(why)
    batch = _Batch(P, int(np.count_nonzero(interior_stations(model.rotor))))
    wrapped, offset = [], 0
    for e in model.chain.effects:
        n = len(e.parameters())
        wrapped.append(_BatchedCorrectionField(e, offset, batch) if isinstance(e, CorrectionFieldEffect)
                       else _BatchedConditions(e, offset, batch))
        offset += n
    chain = EffectChain(wrapped)
    p0 = np.asarray(P, float)[0] if len(P) else model.chain.nominal()

    def solve(draw, conditions):
        batch.draw = np.asarray(draw, int).reshape(-1)
        batch._layout = {}
        return solve_bem(model.rotor, conditions, model.settings, chain, p0, polars=model.polars)

    return solve
