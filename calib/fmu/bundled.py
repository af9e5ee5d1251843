"""The bundled FMU of a workflow (``[model] kind = "fmu"`` with ``variant``), built on demand.

A bundled variant is built for the workflow's rotor and correction grid by :mod:`calib.fmu.build`
(compiled from ``fmu_models/``, cached by source hash); a saved result's model spec records the
same ``build`` table, so ``calib predict`` rebuilds the FMU when its file is gone.
"""

from __future__ import annotations

from pathlib import Path

from calib.errors import InputError


def build_variant(build: dict, source: str = "model", base_dir=None) -> Path:
    """Build (or fetch from the cache) a bundled FMU variant for a rotor table and grid.

    Parameters
    ----------
    build : dict
        ``variant`` ("A" | "B"), ``rotor`` (a workflow ``[rotor]`` table, optional: NREL 5-MW),
        ``grid`` (:meth:`calib.corrections.CorrectionGrid.to_dict`, optional: the default grid).
    """
    from calib.corrections import CorrectionGrid
    from calib.fmu.build import VARIANTS, build_fmu

    variant = str(build.get("variant", "")).upper()
    if variant not in VARIANTS:
        raise InputError(f"unknown FMU variant {build.get('variant')!r}; valid: {', '.join(VARIANTS)}", source,
                         field="model.variant")
    rotor = None
    if build.get("rotor"):
        from calib.rotor.sources import rotor_from_table
        rotor = rotor_from_table(dict(build["rotor"]), source, base_dir).rotor
    grid = CorrectionGrid(**build["grid"]) if build.get("grid") else None
    return Path(build_fmu(variant, rotor, grid))
