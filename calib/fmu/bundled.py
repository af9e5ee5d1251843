"""The bundled FMU of a workflow (``[model] kind = "fmu"`` with ``variant``), built on demand.

A bundled variant is built for the workflow's rotor and correction grid by :mod:`calib.fmu.build`
(compiled from ``fmu_models/``, cached by source hash); a saved result's model spec records the
same ``build`` table, so ``calib predict`` rebuilds the FMU when its file is gone
(:func:`spec_files`).
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


def spec_files(spec: dict, base_dir=None) -> tuple[Path, Path]:
    """The FMU file and the mapping file a model spec names, the FMU rebuilt when its file is gone.

    Parameters
    ----------
    spec : dict
        A model spec (:meth:`calib.fmu.model.FmuModel.spec`): ``fmu``, ``mapping`` and, for a bundled
        variant, ``build`` (:func:`build_variant`).
    base_dir : str or Path, optional
        The folder relative paths are relative to (else they stay as they are).

    Returns
    -------
    fmu, mapping : Path

    Raises
    ------
    InputError
        The spec names no FMU file and no bundled variant to build.
    """
    def resolve(p):
        q = Path(p)
        return q if q.is_absolute() or base_dir is None else Path(base_dir) / q
    fmu = resolve(spec["fmu"]) if spec.get("fmu") else None
    if (fmu is None or not fmu.is_file()) and spec.get("build"):
        fmu = build_variant(spec["build"], "model spec", base_dir)
    if fmu is None:
        raise InputError("the spec names no FMU file", "model spec", field="fmu")
    return fmu, resolve(spec["mapping"])
