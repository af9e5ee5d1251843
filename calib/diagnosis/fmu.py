"""The diagnosis on an FMU (:func:`calib.diagnosis.core.diagnose` with an :class:`FmuFamily`).

A vendor's FMU offers no effect library: what it lets the engineer change are the scalar
parameters its mapping file maps (``[parameters]``: pitch offsets, a stall-delay strength,
...) and, where mapped, a correction field (``[corrections]``). So on an FMU

- *localize* calibrates the FMU's correction field (the mapping must map one);
- the *candidates* are the mapped scalar parameters, each fitted on its own on top of the
  parameters already named (which are fitted again with it, so the models stay nested and
  the likelihood-ratio test of :mod:`calib.diagnosis.core` applies unchanged);
- *recalibrate* calibrates the correction field with the named parameters free.

Everything else (χ² test, likelihood ratio, BIC weights, pattern agreement, ambiguity,
the report) is the native diagnosis's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

from calib.errors import InputError


@dataclass(frozen=True)
class MappedParameter:
    """A candidate of an FMU diagnosis: one mapped scalar parameter."""

    name: str

    def parameters(self) -> list[str]:
        return [self.name]

    def spec(self) -> dict:
        return {"name": self.name, "kind": "fmu parameter"}


class FmuFamily:
    """The models of a diagnosis on an FMU (the calls :func:`calib.diagnosis.core.diagnose` uses).

    Parameters
    ----------
    build : callable(parameters, corrections, channels=None) -> FmuModel
        An FMU model calibrating the mapped scalar ``parameters`` (list of names) and, with
        ``corrections``, the correction field (e.g. a ``[model] kind = "fmu"`` table through
        :func:`calib.models.from_config.model_from_workflow`), with the diagnosis' channels or
        ``channels`` (the separation probes ask for the FMU's other outputs).
    candidates : sequence of str, optional
        Mapped parameters that may be named (default: every one the mapping maps).
    """

    def __init__(self, build: Callable[[list, bool], object], candidates: Sequence[str] | None = None):
        self.build = build
        nominal = build([], False)
        self._nominal = nominal
        mapped = list(nominal.mapping.parameters)
        self.names = tuple(mapped if candidates is None else candidates)
        unknown = [c for c in self.names if c not in mapped]
        if unknown:
            raise InputError(f"unknown FMU parameter(s) {', '.join(unknown)}; the mapping's [parameters]: "
                             f"{', '.join(mapped) or '(none)'}", nominal.mapping.source, field="parameters")
        if nominal.mapping.corrections is None:
            raise InputError("a diagnosis localizes with the correction field, but the mapping maps no "
                             "[corrections]", nominal.mapping.source, field="corrections")
        self.rotor_radius = nominal.rotor_radius
        self.schedule = None    # an FMU states no operating limits: probes keep to the campaign's rotor speeds

    def field_model(self, base=()):
        return self.build([c.name for c in base], True)

    def nominal_model(self):
        return self._nominal

    def variants(self, name: str, options: dict) -> list:
        if options:
            raise InputError(f"an FMU candidate ({name}) takes no options", "diagnosis",
                             field=f"candidate_options.{name}")
        return [(name, MappedParameter(name))]

    def candidate_model(self, base, candidate: MappedParameter):
        return self.build([c.name for c in base] + [candidate.name], False)

    def check(self, base, candidate, conditions) -> None:
        """Mapped parameters were checked when the mapping was loaded: nothing to do."""

    def n_parameters(self, base) -> int:
        return len(base)

    def spec(self, candidate: MappedParameter) -> dict:
        return candidate.spec()

    def add(self, base, best) -> list:
        return list(base) + [MappedParameter(best.name)]

    def names_of(self, base) -> list:
        return [c.name for c in base]

    def probe_channels(self, measured: list) -> list:
        """Channels the separation probes predict: the measured ones and every other steady output
        the mapping maps (per-blade root moments, spanwise normal force, ...)."""
        offered = [c for c in self._nominal.available_channels() if not c.startswith("<")]
        return list(measured) + [c for c in offered if c not in measured]

    def predict(self, base, candidate: MappedParameter, p, conditions, channels: list):
        """A fitted candidate's outputs (``channels``) and their units at ``conditions``."""
        model = self.build([c.name for c in base] + [candidate.name], False, channels)
        try:
            ev = model.evaluate(p, conditions)
        finally:
            if model.capabilities.closes:
                model.close()
        return ev.values, [c.unit for c in model.channels]

    def fingerprint(self, name: str) -> str:
        """A mapped parameter carries no fingerprint (its physics is the vendor's)."""
        return ""

    def kind(self, name: str) -> str:
        """A mapped parameter is a candidate physical effect (the mapping states no model form)."""
        return "physical"
