"""The chain of effects the native BEM evaluates, and its derivative columns.

An effect (any object with the attributes below; the library lives in
:mod:`calib.effects`, which this layer never imports) declares

- ``name`` (str) and ``stage`` (one of :data:`calib.bem.stages.STAGES`);
- ``parameters()``: its :class:`calib.types.Parameter` s, in the order of its slice of ``p``;
- ``apply(theta, state, ctx)``: the stage's state modified for parameter values ``theta``
  (a tuple, one value per parameter: floats, or scalar :class:`~calib.bem.dual.Dual` s
  seeded by the solver when it wants derivatives);

and optionally

- ``order`` (int, default 0): position within its stage; ties keep the chain's order
  (the correction field uses a large order: it is added on top of every other polar effect);
- ``reads_thrust`` (bool, conditions stage): the effect reads ``ctx.thrust``; the solver
  then iterates the solve to a fixed point and differentiates it by the implicit function;
- ``uses_flow`` (bool, polar stage): the effect reads the section's tip-speed ratio or
  Reynolds number (the screen for several roots then tabulates it at their extremes);
- ``n_probes`` (int) with ``probe_map(theta, alpha_deg, ctx)``: for effects with many
  local parameters (see :class:`calib.bem.stages.ProbeMap`); ``apply`` then receives the
  probes as keyword ``probes``;
- ``compiled_polar(theta)`` (polar stage): the effect as a :class:`calib.bem.stages.CompiledPolar`
  (an additive hat-function field with a drag floor) when it is exactly that; a chain whose
  polar stage is that one effect then runs on the compiled kernel (:mod:`calib.bem.kernel`).

Derivative columns of the section pass: 0 the inflow angle φ, 1 the pitch (rad), 2 the
inflow speed V, then each section-stage effect's parameters (or probes) in chain order.
Conditions-stage parameters reach the sections only through V and the pitch.
"""

from __future__ import annotations

from collections import Counter

from dataclasses import dataclass

import numpy as np

from calib.bem import dual as dl
from calib.bem.stages import STAGES
from calib.errors import InputError

COL_PHI, COL_PITCH, COL_WIND = 0, 1, 2
N_BASE_COLUMNS = 3


@dataclass(frozen=True, eq=False)
class ChainEntry:
    """One effect of a chain with where its parameters sit.

    Attributes
    ----------
    effect : object
    offset : int
        Index of its first parameter in ``p``.
    n_params : int
    column : int
        First derivative column (section pass for section stages, point pass for the
        conditions stage); -1 for none.
    n_columns : int
    """

    effect: object
    offset: int
    n_params: int
    column: int
    n_columns: int

    @property
    def probed(self) -> bool:
        return self.effect.n_probes > 0

    def theta(self, p) -> tuple:
        return tuple(float(v) for v in p[self.offset:self.offset + self.n_params])


class EffectChain:
    """An ordered chain of effects with the layout of their parameters.

    Parameters
    ----------
    effects : sequence of calib.effects.base.Effect
        Effects (their declared ``stage``, ``order``, ``n_probes``, ``reads_thrust``, ``uses_flow``) in parameter order: ``p`` is the concatenation of their ``parameters()``.
        They are applied stage by stage (:data:`~calib.bem.stages.STAGES`), within a stage by
        ``order`` and then by their position here.

    Raises
    ------
    InputError
        For an unknown stage, two parameters of the same name, or a probed or
        thrust-reading effect on a stage that does not support it.
    """

    def __init__(self, effects=()):
        effects = tuple(effects)
        self.parameters = []
        offsets = []
        for e in effects:
            stage = e.stage
            if stage not in STAGES:
                raise InputError(f"effect {e.name!r} has stage {stage!r}; valid stages: "
                                 f"{', '.join(STAGES)}", "EffectChain", field="stage")
            if e.n_probes and stage == "conditions":
                raise InputError(f"effect {e.name!r}: probes are for section stages only", "EffectChain")
            if e.reads_thrust and stage != "conditions":
                raise InputError(f"effect {e.name!r}: only conditions-stage effects may read the thrust",
                                 "EffectChain")
            offsets.append(len(self.parameters))
            self.parameters += list(e.parameters())
        names = [q.name for q in self.parameters]
        dup = sorted(n for n, k in Counter(names).items() if k > 1)
        if dup:
            raise InputError(f"parameter name(s) {', '.join(map(repr, dup))} appear twice in the effect chain "
                             f"({', '.join(e.name for e in effects)}); each effect may appear once",
                             "EffectChain", field="effects")
        self.parameters = tuple(self.parameters)
        self.effects = effects
        order = sorted(range(len(effects)), key=lambda i: (STAGES.index(effects[i].stage),
                                                           effects[i].order, i))
        entries = [None] * len(effects)
        point_col, section_col = 0, N_BASE_COLUMNS
        for i in order:      # columns in application order
            e = effects[i]
            n = len(e.parameters())
            if e.stage == "conditions":
                entries[i] = ChainEntry(e, offsets[i], n, point_col, n)
                point_col += n
            else:
                nc = e.n_probes or n
                entries[i] = ChainEntry(e, offsets[i], n, section_col, nc)
                section_col += nc
        self.entries = tuple(entries)
        self._applied = tuple(entries[i] for i in order)
        self.n_point_columns = point_col          # + 1 for the thrust when reads_thrust
        self.n_section_columns = section_col

    # -- layout -----------------------------------------------------------
    @property
    def n_params(self) -> int:
        return len(self.parameters)

    def stage(self, name: str) -> tuple:
        """Entries of one stage in application order."""
        return tuple(e for e in self._applied if e.effect.stage == name)

    @property
    def reads_thrust(self) -> bool:
        return any(e.effect.reads_thrust for e in self.stage("conditions"))

    @property
    def polar_uses_flow(self) -> bool:
        return any(e.effect.uses_flow for e in self.stage("polar"))

    def nominal(self) -> np.ndarray:
        return np.array([q.nominal for q in self.parameters], float)

    def check(self, p) -> np.ndarray:
        """``p`` as floats (nominal values if None); refuses a wrong length or non-finite values."""
        if p is None:
            return self.nominal()
        p = np.asarray(p, float).reshape(-1)
        if p.size != self.n_params:
            raise InputError(f"expected {self.n_params} parameter values for the effect chain "
                             f"({', '.join(e.name for e in self.effects) or 'empty'}), got {p.size}",
                             "solve_bem", field="p")
        bad = np.flatnonzero(~np.isfinite(p))
        if bad.size:
            raise InputError(f"parameter {self.parameters[bad[0]].name!r} is not finite ({p[bad[0]]!r})",
                             "solve_bem", field="p")
        return p

    # -- evaluation -------------------------------------------------------
    def bind(self, p) -> "BoundChain":
        """The chain at parameter values ``p`` (checked; nominal if None)."""
        return BoundChain(self, self.check(p))

    def probes(self, entry: ChainEntry, k: int = 0):
        """Zero probes of ``entry`` (scalar Duals on its columns when k > 0)."""
        if k == 0:
            return (0.0,) * entry.n_columns
        return tuple(dl.Dual.seed(0.0, k, entry.column + j) for j in range(entry.n_columns))


class BoundChain:
    """An :class:`EffectChain` at given parameter values: what the solver runs.

    Attributes
    ----------
    chain : EffectChain
    p : ndarray, shape (n_params,)
    """

    def __init__(self, chain: EffectChain, p: np.ndarray):
        self.chain, self.p = chain, p
        self._stages = {s: chain.stage(s) for s in STAGES}
        self._theta = {id(e): e.theta(p) for e in chain.entries}

    def has(self, stage: str) -> bool:
        return bool(self._stages[stage])

    def theta(self, entry: ChainEntry, k: int = 0):
        """Parameter values of ``entry``: floats, or scalar Duals seeded on its columns when k > 0."""
        values = self._theta[id(entry)]
        if k == 0 or entry.probed:
            return values
        return tuple(dl.Dual.seed(v, k, entry.column + j) for j, v in enumerate(values))

    def run(self, stage: str, state, ctx, k: int = 0):
        """Apply every effect of ``stage`` to ``state`` (derivative columns ``k`` > 0 to seed)."""
        for entry in self._stages[stage]:
            theta = self.theta(entry, k)
            if entry.probed:
                state = entry.effect.apply(theta, state, ctx, probes=self.chain.probes(entry, k))
            else:
                state = entry.effect.apply(theta, state, ctx)
        return state

    # the layout, as on the chain
    @property
    def entries(self):
        return self.chain.entries

    @property
    def n_params(self) -> int:
        return self.chain.n_params

    @property
    def n_section_columns(self) -> int:
        return self.chain.n_section_columns

    @property
    def n_point_columns(self) -> int:
        return self.chain.n_point_columns

    @property
    def reads_thrust(self) -> bool:
        return self.chain.reads_thrust

    @property
    def polar_uses_flow(self) -> bool:
        return self.chain.polar_uses_flow

    def stage(self, name: str) -> tuple:
        return self._stages[name]
