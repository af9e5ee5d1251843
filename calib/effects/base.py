"""The :class:`Effect` base class: a named physical model acting on one stage of the BEM.

An effect declares

- ``name``: its registry name (:data:`calib.effects.EFFECTS`);
- ``stage``: ``"conditions"`` (inflow: wind speed, pitch), ``"polar"`` (C_L, C_D at a
  section's α), ``"induction"`` (loss factors of the momentum balance) or ``"loads"``
  (section loads after the solve), see :mod:`calib.bem.stages`;
- ``parameters()``: its :class:`~calib.types.Parameter` s (nominal, bounds, scale, unit,
  kind ``effect`` or ``nuisance``, prior);
- ``apply(theta, state, ctx)``: the stage's state modified for parameter values ``theta``
  (one per parameter), written with :mod:`calib.bem.dual` so that the same code gives
  values inside the root search and exact derivatives in the solver's dual pass;
- ``fingerprint``: how the effect shows in measured rotor loads (docs/theory.md, Diagnosis), for reports;
- ``n_probes``, ``reads_thrust``, ``uses_flow``, ``order``: what the effect chain must provide (defaults:
  none of it), declared as attributes so that the chain never probes an effect.

and nothing else: no I/O, no state between calls. Options (variants, model constants)
are keyword arguments of the constructor, listed with their defaults in ``OPTIONS`` and
validated there; every effect also takes ``nominal={parameter: value}`` to start from
other nominal values (e.g. the fitted values of an effect added to a model).
"""

from __future__ import annotations

from dataclasses import replace
from typing import ClassVar

import numpy as np

from calib.bem import dual as dl
from calib.errors import InputError
from calib.types import Parameter


class Effect:
    """Base class of the effects of :mod:`calib.effects` (see the module notes).

    Parameters
    ----------
    **options
        The keys of the class's ``OPTIONS`` (their defaults otherwise) and ``nominal``, a dict
        parameter name -> nominal value.

    Raises
    ------
    InputError
        For an unknown option (the message lists the valid ones), an option value outside
        its choices, or a nominal value for an unknown parameter or outside the bounds. A
        nominal value past a bound by no more than :data:`NOMINAL_ROUND_OFF` × the
        parameter's scale (round-off of a fitted value that ended on the bound) is taken as
        the bound.
    """

    name: ClassVar[str] = ""
    stage: ClassVar[str] = ""
    fingerprint: ClassVar[str] = ""
    order: ClassVar[int] = 0
    #: "physical" (a missing effect of the flow or the rotor) or "model_form" (the BEM's own
    #: approximation, e.g. its induction model): a diagnosis names the second kind as model form
    kind: ClassVar[str] = "physical"
    #: declared capabilities (the chain reads them; it never probes): section probes the effect
    #: tabulates its θ-derivatives on (section stages only), whether it reads the rotor thrust
    #: (conditions stage only) and whether its polar depends on the local flow (Re, chord/r)
    n_probes: int = 0
    reads_thrust: bool = False
    uses_flow: bool = False
    OPTIONS: ClassVar[dict] = {}
    CHOICES: ClassVar[dict] = {}
    PARAMETERS: ClassVar[tuple] = ()

    def __init__(self, **options):
        nominal = options.pop("nominal", None) or {}
        unknown = sorted(set(options) - set(self.OPTIONS))
        if unknown:
            valid = ", ".join(list(self.OPTIONS) + ["nominal"])
            raise InputError(f"unknown option(s) {', '.join(map(repr, unknown))} of effect {self.name!r}; "
                             f"valid: {valid}", f"effect {self.name!r}", field=unknown[0])
        self.options = {**self.OPTIONS, **options}
        for key, choices in self.CHOICES.items():
            if self.options[key] not in choices:
                raise InputError(f"option {key} = {self.options[key]!r} of effect {self.name!r}; valid: "
                                 f"{', '.join(map(str, choices))}", f"effect {self.name!r}", field=key)
        params = {q.name: q for q in self._parameters()}
        for key, value in nominal.items():
            if key not in params:
                raise InputError(f"no parameter {key!r} in effect {self.name!r}; its parameters: "
                                 f"{', '.join(params)}", f"effect {self.name!r}", field="nominal")
            try:
                params[key] = replace(params[key], nominal=_within_round_off(params[key], float(value)))
            except InputError as exc:
                raise InputError(exc.message, f"effect {self.name!r}", field=f"nominal.{key}") from None
        self._nominal = {k: params[k].nominal for k in nominal}
        self._params = tuple(params.values())

    # -- declaration ------------------------------------------------------
    def _parameters(self) -> tuple[Parameter, ...]:
        """The parameters before nominal overrides (subclasses with option-dependent parameters override)."""
        return tuple(self.PARAMETERS)

    def parameters(self) -> tuple[Parameter, ...]:
        """The effect's parameters, in the order of its slice of the model's ``p``."""
        return self._params

    def apply(self, theta, state, ctx):
        """The stage's state modified for parameter values ``theta`` (see the module notes)."""
        raise NotImplementedError

    # -- description ------------------------------------------------------
    def spec(self) -> dict:
        """``{"name": ..., "options": {...}}``, JSON-able; :func:`calib.effects.effect_from_spec` rebuilds it."""
        options = {k: _jsonable(v) for k, v in self.options.items()}
        if self._nominal:
            options["nominal"] = dict(self._nominal)
        return {"name": self.name, "options": options}

    def describe(self) -> dict:
        """Name, stage, options, parameters and fingerprint as plain data."""
        return {"name": self.name, "stage": self.stage, "options": self.spec()["options"],
                "parameters": [{"name": q.name, "nominal": q.nominal, "lower": q.lower, "upper": q.upper,
                                "scale": q.scale, "unit": q.unit, "kind": str(q.kind), "prior_std": q.prior_std,
                                "description": q.description} for q in self.parameters()],
                "fingerprint": self.fingerprint}

    def __repr__(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self.spec()["options"].items())
        return f"{type(self).__name__}({opts})"


#: A nominal value past a bound by at most this fraction of the parameter's scale is round-off [-].
NOMINAL_ROUND_OFF = 1e-9


def _within_round_off(q: Parameter, value: float) -> float:
    """``value`` moved onto the bound of ``q`` it passes by round-off only, else unchanged
    (so that :class:`~calib.types.Parameter` still refuses a value truly outside its bounds)."""
    tol = NOMINAL_ROUND_OFF * abs(q.scale)
    if q.lower - tol <= value < q.lower:
        return float(q.lower)
    if q.upper < value <= q.upper + tol:
        return float(q.upper)
    return value


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.floating, np.integer)):
        return v.item()
    if isinstance(v, tuple):
        return list(v)
    return v


# -- smooth shapes shared by the effects (dual-compatible) --------------------
def smoothstep(x):
    """C¹ ramp S(x) = x²(3 − 2x) on [0, 1], 0 below, 1 above [-] (array or Dual)."""
    xv = dl.value(x)
    inner = x * x * (3.0 - 2.0 * x)
    return dl.where(xv <= 0.0, 0.0 * x, dl.where(xv >= 1.0, 0.0 * x + 1.0, inner))


def attached_weight(alpha_deg, full_deg: float, end_deg: float):
    """1 for |α| <= ``full_deg``, falling smoothly (C¹) to 0 at |α| = ``end_deg`` [-]."""
    return 1.0 - smoothstep((dl.absolute(alpha_deg) - full_deg) / (end_deg - full_deg))


def stall_weight(alpha_deg, alpha_stall_deg, width_deg: float = 8.0, full_deg: float = 25.0, end_deg: float = 45.0):
    """0 below α_stall − ``width_deg``, rising (C¹) to 1 at the stall angle, back to 0 from
    ``full_deg`` to ``end_deg`` (deep stall) [-]: where a loss of C_L,max acts."""
    rise = smoothstep((alpha_deg - (alpha_stall_deg - width_deg)) / width_deg)
    return rise * (1.0 - smoothstep((alpha_deg - full_deg) / (end_deg - full_deg)))
