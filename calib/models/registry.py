"""Model kinds by name: rebuild a forward model from the ``spec()`` a result recorded."""

from __future__ import annotations

from pathlib import Path

from calib.errors import InputError


def _bem(spec, base_dir, source):
    from calib.models.bem_model import BemModel

    return BemModel.from_spec(spec, base_dir, source)


def _fmu(spec, base_dir, source):
    from calib.fmu.model import FmuModel

    check_fmu_files(spec, base_dir, source)
    return FmuModel.from_spec(spec, base_dir)


#: Model kind -> builder(spec, base_dir, source).
MODEL_KINDS = {"bem": _bem, "fmu": _fmu}


def model_kind(kind, source, field: str = "kind") -> str:
    """``kind`` when it names a model kind of :data:`MODEL_KINDS`, else the one error every entry
    point gives (a recorded spec, a workflow's ``[model]`` table, a model built from a table).

    Parameters
    ----------
    kind : object
        The value given.
    source : str or Path
        Where it was given (named in the error).
    field : str
        Its key there (``kind`` or ``model.kind``).

    Raises
    ------
    InputError
        Not a model kind; the message lists the valid ones.
    """
    if kind not in MODEL_KINDS:
        raise InputError(f"unknown model kind {kind!r}; valid kinds: {', '.join(MODEL_KINDS)}", source, field=field)
    return kind


def check_fmu_files(spec: dict, base_dir=None, source: str = "model spec") -> None:
    """Refuse an FMU spec whose recorded FMU or mapping file is missing or changed.

    Paths resolve as :meth:`calib.fmu.model.FmuModel.from_spec` resolves them
    (absolute, else relative to ``base_dir``). The FMU must exist unless the spec names a
    bundled variant to build again (``build``: then its bytes are not checked, a compiler may
    build it again differently); where ``fmu_sha256`` (``mapping_sha256``) is recorded, the file
    found must still have that SHA-256.

    Raises
    ------
    InputError
        Naming the spec key and the file: missing, or changed since the run (both digests
        shortened).
    """
    from calib.measurements import sha256_of

    def resolve(p):
        q = Path(p)
        return q if q.is_absolute() or base_dir is None else Path(base_dir) / q

    for key, rebuildable in (("fmu", bool(spec.get("build"))), ("mapping", False)):
        value = spec.get(key)
        if not isinstance(value, str) or not value:
            continue
        path = resolve(value)
        if not path.is_file():
            if rebuildable:
                continue                    # a bundled variant: from_spec builds it again
            raise InputError(f"the {key} file {path} the run used is missing; restore it to rebuild the model",
                             source, field=key)
        recorded = spec.get(f"{key}_sha256")
        if rebuildable:
            continue                        # a bundled variant built again need not repeat its bytes
        if isinstance(recorded, str) and recorded:
            now = sha256_of(path)
            if now != recorded:
                raise InputError(f"the {key} file {path} changed since the run (SHA-256 {recorded[:12]}... "
                                 f"recorded, {now[:12]}... now); restore the file the run used", source, field=key)


def build_model(spec: dict, base_dir=None, source: str = "model spec"):
    """Rebuild a forward model from its ``spec()`` dict.

    Parameters
    ----------
    spec : dict
        Must hold ``kind``, one of :data:`MODEL_KINDS`.
    base_dir : str or Path, optional
        Folder that relative file paths in the spec are relative to, and where files missing
        from their recorded places are looked for (a result's folder).
    source : str
        Where the spec came from (named in errors).

    Raises
    ------
    InputError
        Unknown kind, a missing key, or recorded files missing or changed (named).
    """
    kind = model_kind(spec.get("kind") if isinstance(spec, dict) else None, source)
    try:
        return MODEL_KINDS[kind](spec, base_dir, source)
    except KeyError as exc:
        raise InputError(f"model spec lacks key {exc.args[0]!r}", source, field=str(exc.args[0])) from None
