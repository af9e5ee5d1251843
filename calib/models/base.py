"""The ForwardModel contract: everything the calibrator knows about a model.

A forward model exposes ordered scalar :class:`Parameter` s, named output
:class:`Channel` s with units, and two calls over a batch of
:class:`OperatingConditions`:

``evaluate(p, conditions) -> Evaluation``
    values (n_points, n_channels) and a per-point status.
``jacobian(p, conditions) -> (Evaluation, G)``
    ``G[k, c, j] = d values[k, c] / d p[j]``, shape (n_points, n_channels, n_params).

Failed points carry a non-zero status and a message; their values are NaN *and*
flagged, never silently NaN.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from calib.types import Channel, Evaluation, OperatingConditions, Parameter

#: how a model's ``jacobian`` is computed: analytic sensitivities, or finite differences of simulations
DERIVATIVE_KINDS = ("exact", "finite_difference")


@dataclass(frozen=True)
class Capabilities:
    """What a model offers beyond ``evaluate`` and ``jacobian``: declared by the model, never probed.

    Attributes
    ----------
    name : str
        The model's name in results and reports (e.g. ``"BemModel"``); a wrapper (the history's
        :class:`~calib.models.recorded_model.RecordedModel`) passes its model's on, so results are the same with and
        without it.
    correction_field : bool
        ``correction_field()`` returns the model's additive polar-correction field
        (:class:`~calib.parametrizations.correction_field.CorrectionField`): eigenshapes, the C_D floor,
        polar bands.
    refinable : bool
        ``with_grid(grid)`` returns the same model on another correction grid (the field between the
        nodes, :mod:`calib.parametrizations.aliasing`; the tightening advice).
    rebuildable : bool
        ``spec()`` describes the model as a JSON-able dict that :func:`calib.models.registry.build_model`
        rebuilds (``calib predict``), and ``rotor_radius`` [m] (or None) gives reports the tip-speed ratio.
    derivatives : {"exact", "finite_difference"}
        How ``jacobian`` is computed.
    closes : bool
        ``close()`` releases worker processes or files; a caller that built the model calls it.
    difference_step : float or None
        With ``derivatives="finite_difference"``: the difference step of ``jacobian`` [scale units, i.e. a
        fraction of each parameter's ``scale``]; None when not declared.
    """

    name: str
    correction_field: bool = False
    refinable: bool = False
    rebuildable: bool = False
    derivatives: str = "finite_difference"
    closes: bool = False
    difference_step: float | None = None

    def __post_init__(self):
        if self.derivatives not in DERIVATIVE_KINDS:
            raise ValueError(f"derivatives must be one of {DERIVATIVE_KINDS}, got {self.derivatives!r}")
        if self.refinable and not self.correction_field:
            raise ValueError("a refinable model must have a correction field")


@runtime_checkable
class ForwardModel(Protocol):
    """The adapter contract (docs/theory.md, Architecture).

    ``capabilities`` declares the optional calls the model offers (:class:`Capabilities`); the
    calibrator, the workflow and the history ask it, never the model's attributes.
    """

    @property
    def capabilities(self) -> Capabilities: ...

    @property
    def parameters(self) -> tuple[Parameter, ...]: ...

    @property
    def channels(self) -> tuple[Channel, ...]: ...

    def evaluate(self, p: np.ndarray, conditions: OperatingConditions) -> Evaluation: ...

    def jacobian(self, p: np.ndarray, conditions: OperatingConditions) -> tuple[Evaluation, np.ndarray]: ...


@runtime_checkable
class FieldModel(Protocol):
    """The calls of a model whose ``capabilities.correction_field`` is true.

    What only a correction field has: eigenshapes, the C_D ≥ C_D,min bound, polar bands.
    """

    def correction_field(self) -> "CorrectionField": ...


@runtime_checkable
class RefinableFieldModel(Protocol):
    """The calls of a model whose ``capabilities.refinable`` is true: rebuilt on another correction grid.

    The calibrator uses it for the part of the field between the nodes that the data see
    (:mod:`calib.parametrizations.aliasing`); a field model without it gets bands without
    that term.
    """

    def correction_field(self) -> "CorrectionField": ...

    def with_grid(self, grid) -> "RefinableFieldModel": ...


@runtime_checkable
class RebuildableModel(Protocol):
    """The calls of a model whose ``capabilities.rebuildable`` is true: it describes itself so a saved
    result can rebuild it.

    ``spec()`` returns a JSON-able dict with a ``kind`` key understood by
    :func:`calib.models.registry.build_model`; ``rotor_radius`` [m] (or ``None``) lets
    reports use the tip-speed ratio.
    """

    def spec(self) -> dict: ...

    @property
    def rotor_radius(self) -> float | None: ...


from calib.parametrizations.correction_field import CorrectionField  # noqa: E402  (for annotations)
