"""An FMU's variables as a mapping uses them: lookup, role checks, array sizes, start values, types.

:class:`Variables` wraps fmpy's model description: a variable by name (an unknown one refused with
"did you mean"), its causality and variability checked against the role a mapping gives it, the
size of an (FMI 3) array variable and its start values. :func:`type_class` sorts FMI types into
the kinds calib writes and reads (real, integer, boolean). Errors are
:class:`~calib.fmu.archive.FmuInputError` naming the mapping file and the key.
"""

from __future__ import annotations

from calib.fmu import plan as fp
from calib.fmu.archive import FmuInputError


class Variables:
    """The model description's variables as a mapping uses them: lookup (with "did you mean"),
    causality and variability checks, array sizes, start values.

    Parameters
    ----------
    model_description : fmpy.model_description.ModelDescription
    fmu_name : str
        The FMU's file name, for messages.
    source : str
        The mapping file, which errors name.
    """

    def __init__(self, model_description, fmu_name: str, source: str):
        self.by_name = {v.name: v for v in model_description.modelVariables}
        self.fmu_name = fmu_name
        self.source = source

    def get(self, name: str, where: str):
        """The variable ``name`` (``where``: the mapping key that names it, for the error)."""
        v = self.by_name.get(name)
        if v is None:
            from difflib import get_close_matches
            close = get_close_matches(name, list(self.by_name), n=3)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise FmuInputError(f"variable {name!r} does not exist in {self.fmu_name}{hint}",
                                self.source, field=where)
        return v

    def expect(self, var, where: str, causality: tuple, variability: tuple | None = None, what: str = ""):
        if var.causality not in causality:
            raise FmuInputError(f"variable {var.name!r} has causality {var.causality!r}; {what or 'expected'} "
                                f"{' or '.join(causality)}", self.source, field=where)
        if variability and var.variability not in variability:
            raise FmuInputError(f"variable {var.name!r} is not tunable (variability {var.variability!r}): it "
                                f"cannot change after initialization, so it cannot be calibrated (perturbed "
                                f"runs restart from a settled state); expected variability "
                                f"{' or '.join(variability)}", self.source, field=where)

    def size(self, var) -> int:
        n = 1
        for d in var.dimensions or []:
            if d.start is not None:
                n *= int(d.start)
            else:
                ref = d.variable if d.variable is not None else None
                n *= int(float(ref.start)) if ref is not None and ref.start is not None else 1
        return n

    def start_values(self, var, size: int) -> list:
        if var.start is None:
            return [0.0] * size
        vals = str(var.start).split()
        out = []
        for v in vals:
            out.append({"true": 1.0, "false": 0.0}.get(v.lower(), None) if v.lower() in ("true", "false")
                       else float(v))
        return (out * size)[:size] if len(out) == 1 else out[:size]


def type_class(var) -> str:
    """The kind of value an FMI variable holds, whatever its FMI version spells the type.

    Parameters
    ----------
    var : fmpy.model_description.ModelVariable
        The variable.

    Returns
    -------
    str
        ``"real"`` (:data:`calib.fmu.plan.REAL_TYPES`: Real, Float64), ``"integer"`` (Integer, Int32,
        Enumeration), ``"boolean"`` (Boolean), or the FMI type name itself for any other (Float32,
        String ...), which calib neither writes nor reads.
    """
    if var.type in fp.REAL_TYPES:
        return "real"
    if var.type in fp.INTEGER_TYPES:
        return "integer"
    if var.type in fp.BOOLEAN_TYPES:
        return "boolean"
    return var.type
