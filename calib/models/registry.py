"""Model kinds by name: rebuild a forward model from the ``spec()`` a result recorded."""

from __future__ import annotations

from calib.errors import InputError


def _bem(spec, base_dir):
    from calib.models.bem_model import BemModel

    return BemModel.from_spec(spec, base_dir)


def _fmu(spec, base_dir):
    from calib.models.fmu_model import FmuModel

    return FmuModel.from_spec(spec, base_dir)


#: Model kind -> builder(spec, base_dir).
MODEL_KINDS = {"bem": _bem, "fmu": _fmu}


def build_model(spec: dict, base_dir=None, source: str = "model spec"):
    """Rebuild a forward model from its ``spec()`` dict.

    Parameters
    ----------
    spec : dict
        Must hold ``kind``, one of :data:`MODEL_KINDS`.
    base_dir : str or Path, optional
        Folder that relative file paths in the spec are relative to.
    source : str
        Where the spec came from (named in errors).
    """
    kind = spec.get("kind") if isinstance(spec, dict) else None
    if kind not in MODEL_KINDS:
        raise InputError(f"unknown model kind {kind!r}; valid kinds: {', '.join(MODEL_KINDS)}", source,
                         field="kind")
    try:
        return MODEL_KINDS[kind](spec, base_dir)
    except KeyError as exc:
        raise InputError(f"model spec lacks key {exc.args[0]!r}", source, field=str(exc.args[0])) from None
