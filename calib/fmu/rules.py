"""How the FMU adapter runs and differentiates an FMU: the ``[steady]`` and ``[jacobian]`` tables.

:class:`SteadyRule` says how long a run settles and averages (whole revolutions, the windows at a
rotor speed) and :class:`JacobianRule` how the adapter takes central differences. Both are read and
validated here (:func:`steady_rule`, :func:`jacobian_rule`) for :func:`calib.fmu.mapping.load_mapping`,
which refuses a wrong key or value with :class:`~calib.errors.InputError` naming the file and the key.
A :class:`SteadyRule` travels to the worker
processes inside each :class:`~calib.fmu.plan.SimulationPlan`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from calib.config import NUM, Key, settings_from_table
from calib.errors import InputError

_STEADY_KEYS = {"steps_per_revolution": Key(int, True), "settle_revolutions": Key(int, True),
                "average_revolutions": Key(int, True), "standstill_step_size": Key(NUM),
                "convergence_rtol": Key(NUM), "perturbation_settle_revolutions": Key(int),
                "perturbation_average_revolutions": Key(int), "settle_rtol": Key(NUM)}
#: upper bounds of the step counts: a larger one is a typo, and would run the FMU for days
_STEADY_MAX = {"steps_per_revolution": 100_000, "settle_revolutions": 10_000, "average_revolutions": 10_000,
               "perturbation_settle_revolutions": 10_000, "perturbation_average_revolutions": 10_000}
_JACOBIAN_KEYS = {"relative_step": Key(NUM), "warm_start": Key(bool), "differences": Key(str)}
#: Finite-difference schemes: runs per parameter and point
DIFFERENCES = {"central": 2, "forward": 1}


@dataclass(frozen=True)
class SteadyRule:
    """Steady averages over whole revolutions (``fmu_models/README.md``, "[steady]")."""

    steps_per_revolution: int
    settle_revolutions: int
    average_revolutions: int
    standstill_step_size: float = 0.05
    convergence_rtol: float = 2e-3
    perturbation_settle_revolutions: int | None = None
    perturbation_average_revolutions: int | None = None
    #: None: settle ``settle_revolutions`` always. A number: a cold run settles until the halves of its averaging
    #: window agree to this (relative, as ``convergence_rtol``), revolution by revolution, at most
    #: ``settle_revolutions`` (:func:`calib.fmu.settling.settled_window`)
    settle_rtol: float | None = None

    def __post_init__(self):
        # a perturbed run restored from the settled base state settles and averages like the base
        # run unless the mapping says that less is enough for this FMU
        if self.perturbation_settle_revolutions is None:
            object.__setattr__(self, "perturbation_settle_revolutions", self.settle_revolutions)
        if self.perturbation_average_revolutions is None:
            object.__setattr__(self, "perturbation_average_revolutions", self.average_revolutions)

    def perturbation_window(self, rotor_speed: float) -> tuple[float, int, int]:
        """Step [s], settling and averaging step counts of a run restored from the base state."""
        step, _, _ = self.window(rotor_speed)
        n = self.steps_per_revolution
        return step, self.perturbation_settle_revolutions * n, self.perturbation_average_revolutions * n

    def window(self, rotor_speed: float) -> tuple[float, int, int]:
        """Communication step [s], settling and averaging step counts at ``rotor_speed`` [rpm].

        One revolution is exactly ``steps_per_revolution`` steps, so both windows are whole
        revolutions; at standstill the same counts of ``standstill_step_size`` are used.
        """
        n = self.steps_per_revolution
        step = 60.0 / (rotor_speed * n) if rotor_speed > 0 else float(self.standstill_step_size)
        return step, self.settle_revolutions * n, self.average_revolutions * n

    def replace(self, **changes) -> "SteadyRule":
        """A copy with some fields changed (validated)."""
        data = {k: getattr(self, k) for k in self.__dataclass_fields__ if getattr(self, k) is not None} | changes
        return steady_rule(data, "steady settings", "steady")


@dataclass(frozen=True)
class JacobianRule:
    """How the adapter differentiates: central (two runs per parameter, error O(h²)) or forward
    differences (one run per parameter against the point's base run, error O(h)), and their warm start.

    Default forward at ``relative_step`` 0.1 (× each parameter's scale): a steady FMU output averaged
    over a finite window jumps at isolated parameter values (the bundled FMU: ~0.014 noise σ), and a step
    of 0.01 scale measures the jump instead of the slope. Measured on the bundled FMU's diagnosis model
    (``benchmarks/bench_fmu_diagnosis.py difference-error A``, error against central 0.2): stall-delay
    strength column central 0.01 87 %, forward 0.1 11 %, central 0.1 3 %; forward takes half the runs."""

    relative_step: float = 0.1
    warm_start: bool = True
    differences: str = "forward"


def steady_rule(s: dict, source: str, where: str = "steady") -> SteadyRule:
    """The validated ``[steady]`` table ``s`` (``where``: its name in messages; ``source``: the file)."""
    rule = settings_from_table(SteadyRule, s, where, source, _STEADY_KEYS)
    positive = {"steps_per_revolution": 1, "average_revolutions": 1, "perturbation_average_revolutions": 1}
    for key in (k for k in _STEADY_KEYS if k != "settle_rtol"):
        value = getattr(rule, key)
        low = positive.get(key, 0)
        high = _STEADY_MAX.get(key, float("inf"))
        if not (math.isfinite(value) and low <= value <= high):
            raise InputError(f"'{where}.{key}' must be in [{low}, {high:g}], got {value!r}", source,
                             field=f"{where}.{key}")
    if rule.settle_rtol is not None and not (math.isfinite(rule.settle_rtol) and rule.settle_rtol > 0):
        raise InputError(f"'{where}.settle_rtol' must be a number > 0 (or left out: settle "
                         f"'{where}.settle_revolutions' always), got {rule.settle_rtol!r}", source,
                         field=f"{where}.settle_rtol")
    if not rule.standstill_step_size > 0 or not rule.convergence_rtol > 0:
        raise InputError(f"'{where}.standstill_step_size' and '{where}.convergence_rtol' must be > 0", source,
                         field=where)
    if rule.average_revolutions % 2:
        raise InputError(f"'{where}.average_revolutions' must be even (the convergence check compares two halves "
                         f"of whole revolutions), got {rule.average_revolutions}", source,
                         field=f"{where}.average_revolutions")
    if rule.steps_per_revolution < 8:
        raise InputError(f"'{where}.steps_per_revolution' must be >= 8 (3P harmonics need more than 6 samples "
                         f"per revolution), got {rule.steps_per_revolution}", source,
                         field=f"{where}.steps_per_revolution")
    return rule


def jacobian_rule(data: dict, src: str) -> JacobianRule:
    """``[jacobian]`` of the mapping file's content ``data``: the finite-difference rule."""
    jac = data.get("jacobian", {})
    jacobian = settings_from_table(JacobianRule, jac, "jacobian", src, _JACOBIAN_KEYS)
    if not 0 < jacobian.relative_step <= 0.5:
        raise InputError(f"'jacobian.relative_step' must be in (0, 0.5], got {jacobian.relative_step!r}", src,
                         field="jacobian.relative_step")
    check_differences(jacobian.differences, src)
    return jacobian


def check_differences(value, src: str) -> str:
    """``value`` if it names a scheme of :data:`DIFFERENCES`, else :class:`~calib.errors.InputError` naming them."""
    if value not in DIFFERENCES:
        raise InputError(f"'jacobian.differences' must be one of {', '.join(DIFFERENCES)}, got {value!r}", src,
                         field="jacobian.differences")
    return value
