"""What of an effect chain the compiled BEM kernel (:mod:`calib.bem.kernel`) runs, and the data it reads.

:func:`chain_form` says whether the kernel can run a chain's section stages (no induction
effect; no polar effect, or a single one the kernel evaluates, ``compiled_polar``);
:func:`node_table` lays out the polar tables for it; :func:`compiled_pass` is the section pass
with derivatives on the kernel (:func:`calib.bem.sections.section_pass`).
"""

from __future__ import annotations

import weakref

import numpy as np

from calib.bem import dual as dl

_TABLES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def node_table(polars) -> tuple[np.ndarray, np.ndarray]:
    """The polars as the kernel reads them, once per :class:`SectionPolars`.

    Returns
    -------
    table : ndarray, shape (n_tables, n_grid, 4)
        Per distinct station table and α node: C_L, h dC_L/dα, C_D, h dC_D/dα (h the grid step
        [deg]; the products :meth:`SectionPolars.lookup` forms), so that a look-up reads two
        adjacent nodes from one place.
    row : ndarray of int, shape (n_stations,)
        The table of each station.
    """
    if polars not in _TABLES:
        h = polars.step_deg
        per_station = np.stack([polars.cl_nodes, polars.cl_slopes * h, polars.cd_nodes, polars.cd_slopes * h], axis=-1)
        flat = per_station.reshape(per_station.shape[0], -1)
        _, first, row = np.unique(flat, axis=0, return_index=True, return_inverse=True)
        _TABLES[polars] = (np.ascontiguousarray(per_station[first]), np.ascontiguousarray(row.reshape(-1), np.int64))
    return _TABLES[polars]


def chain_form(chain):
    """Whether the kernel can run the section stages of ``chain`` (a :class:`calib.bem.chain.BoundChain`),
    and its polar stage for it.

    Returns
    -------
    compilable : bool
        No induction effect, and no polar effect or a single one with ``compiled_polar``.
    field : calib.bem.stages.CompiledPolar or None
    """
    if chain.has("induction"):
        return False, None
    entries = chain.stage("polar")
    if not entries:
        return True, None
    form = getattr(entries[0].effect, "compiled_polar", None)
    if len(entries) > 1 or form is None:
        return False, None
    return True, form(chain.theta(entries[0]))


def compiled_pass(sec, roots, chain, k: int) -> tuple:
    """The section pass on ``k`` derivative columns by the compiled kernel that found ``roots`` (values
    as without derivatives, exact derivatives in one forward-mode pass and the implicit-function step;
    no loads-stage effect).

    Returns
    -------
    tuple
        The fields of :class:`calib.bem.sections.SectionValues`, ``totals`` included.
    """
    v = roots.compiled.values(roots.phi)
    probe = chain.stage("polar")[0].column if chain.has("polar") else -1
    d = roots.compiled.derivatives(roots.phi, k, sec.vx_per_wind, sec.vy_per_wind, probe)
    eq = {"residual": dl.Dual(v["residual"], d["residual"]), "a": v["a"], "ap": v["ap"], "cn": v["cn"],
          "ct": v["ct"], "F": v["F"], "load": 1.0}
    quantities = {"Np": dl.Dual(v["Np"], d["Np"]), "Tp": dl.Dual(v["Tp"], d["Tp"]),
                  "cn": dl.Dual(v["cn_chord"], d["cn"]), "ct": dl.Dual(v["ct_chord"], d["ct"]),
                  "alpha_deg": dl.Dual(v["alpha_deg"], d["alpha_deg"])}
    totals = roots.compiled.totals(roots.converged, sec.sel, sec.shape)
    return v["alpha_deg"], v["cl"], v["cd"], eq, v["W"], quantities, totals
