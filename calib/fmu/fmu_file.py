"""An FMU file opened for the adapter: checked, its model description read, matched to its mapping, extracted.

:func:`open_fmu` does, in this order, what :class:`calib.fmu.model.FmuModel` needs of the file
before it binds the mapping, refusing with :class:`~calib.fmu.archive.FmuInputError` naming the
file (or the mapping file) and the item:

- the file is a zip archive whose entries all stay inside the extraction folder
  (:func:`calib.fmu.archive.check_archive`);
- ``modelDescription.xml`` parses (fmpy) and offers co-simulation; a binary for this platform
  exists (:func:`calib.fmu.archive.platform_binary`);
- non-fatal findings of fmpy's validation are issued as warnings;
- the mapping's ``fmi_version`` and ``model_identifier``, when it states them, are the FMU's;
- the file is extracted once, cached by its SHA-256 (:func:`calib.fmu.archive.extract_once`).

The answer is an :class:`FmuFile`: the model description, the file's identity and its declared
state and derivative capabilities.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

from calib.fmu.archive import FmuInputError, check_archive, extract_once, platform_binary
from calib.fmu.mapping import Mapping
from calib.measurements import sha256_of


@dataclass(frozen=True)
class FmuFile:
    """An FMU file as :func:`open_fmu` found it.

    Attributes
    ----------
    model_description : fmpy.model_description.ModelDescription
        As fmpy reads it.
    binary : str
        Path inside the archive of the shared library for this platform.
    sha256 : str
        SHA-256 of the file (its identity, and the key of its extraction folder).
    unzip_dir : str
        The folder it is extracted to.
    guid : str
        The GUID (FMI 2) or instantiation token (FMI 3).
    can_get_state, can_serialize : bool
        The FMU can save and restore its state, and serialize it to bytes.
    offers_directional_derivatives : bool
        The FMU declares directional derivatives.
    """

    model_description: object
    binary: str
    sha256: str
    unzip_dir: str
    guid: str
    can_get_state: bool
    can_serialize: bool
    offers_directional_derivatives: bool


def open_fmu(path: Path, mapping: Mapping, warn_stacklevel: int = 2) -> FmuFile:
    """Check, read and extract the FMU ``path`` for ``mapping`` (see the module docstring).

    Parameters
    ----------
    path : Path
        The ``.fmu`` file (resolved).
    mapping : Mapping
        Its mapping (its ``fmi_version`` and ``model_identifier`` are checked against the FMU).
    warn_stacklevel : int
        Whom fmpy's validation warnings name, counted from the caller of this function (1: that
        caller, 2: its caller ...).

    Returns
    -------
    FmuFile

    Raises
    ------
    FmuInputError
        Not a safe zip archive, no readable model description, no co-simulation interface, no
        binary for this platform (naming the FMU file), or an FMI version or model identifier
        other than the mapping's (naming the mapping file).
    """
    src = str(path)
    names = check_archive(path)
    md = _read_description(src)
    binary = platform_binary(md, names, src)
    _validation_warnings(src, warn_stacklevel + 2)
    _check_mapping_identity(md, mapping, path.name)
    sha256 = sha256_of(path)
    cs = md.coSimulation
    return FmuFile(md, binary, sha256, extract_once(path, sha256),
                   md.guid if md.fmiVersion.startswith("2") else md.instantiationToken,
                   bool(getattr(cs, "canGetAndSetFMUstate", False)), bool(getattr(cs, "canSerializeFMUstate", False)),
                   bool(getattr(cs, "providesDirectionalDerivative", False)))


def _read_description(src: str):
    """fmpy's model description of the FMU file ``src``, which must offer co-simulation."""
    from fmpy.model_description import read_model_description

    try:
        md = read_model_description(src, validate=False)
    except Exception as exc:  # noqa: BLE001 - fmpy raises several kinds
        raise FmuInputError(f"modelDescription.xml cannot be read: {exc}", src, field="modelDescription.xml") \
            from None
    if md.coSimulation is None:
        raise FmuInputError("the FMU has no co-simulation interface (model exchange only); calib drives "
                            "co-simulation FMUs", src, field="modelDescription.xml")
    return md


def _validation_warnings(src: str, stacklevel: int) -> None:
    """fmpy's validation findings on the FMU file ``src``, each a warning (a crash of the validator too)."""
    try:
        from fmpy.validation import validate_fmu
        problems = validate_fmu(src)
    except Exception as exc:  # noqa: BLE001 - a validator crash is itself only a finding
        problems = [f"fmpy validation could not run: {exc}"]
    for problem in problems or []:
        warnings.warn(f"{src}: fmpy validate: {problem}", stacklevel=stacklevel)


def _check_mapping_identity(md, m: Mapping, fmu_name: str) -> None:
    """The FMI version and model identifier the mapping states (when it does) are the FMU's."""
    if m.fmi_version and m.fmi_version != md.fmiVersion:
        raise FmuInputError(f"the mapping is for FMI {m.fmi_version}, the FMU {fmu_name} is FMI "
                            f"{md.fmiVersion}", m.source, field="fmi_version")
    ident = md.coSimulation.modelIdentifier
    if m.model_identifier and m.model_identifier != ident:
        raise FmuInputError(f"the mapping is for model identifier {m.model_identifier!r}, the FMU "
                            f"{fmu_name} is {ident!r}", m.source, field="model_identifier")
