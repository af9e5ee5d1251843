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

from typing import Protocol, runtime_checkable

import numpy as np

from calib.types import (CONDITION_FIELDS, Channel, Evaluation, OperatingConditions, Parameter,  # noqa: F401
                         ParameterKind, Status, StatusCounts, check_parameter_vector, nominal_vector)


@runtime_checkable
class ForwardModel(Protocol):
    """The adapter contract (docs/theory.md, Architecture)."""

    @property
    def parameters(self) -> tuple[Parameter, ...]: ...

    @property
    def channels(self) -> tuple[Channel, ...]: ...

    def evaluate(self, p: np.ndarray, conditions: OperatingConditions) -> Evaluation: ...

    def jacobian(self, p: np.ndarray, conditions: OperatingConditions) -> tuple[Evaluation, np.ndarray]: ...


@runtime_checkable
class FieldModel(Protocol):
    """Optional: a model whose parameters include an additive polar-correction field.

    The calibrator asks through this protocol (never by probing attributes) for what
    only a correction field has: eigenshapes, the C_D ≥ C_D,min bound, polar bands.
    """

    def correction_field(self) -> "CorrectionField": ...


@runtime_checkable
class RefinableFieldModel(Protocol):
    """Optional: a field model that can be rebuilt on another correction grid.

    The calibrator uses it for the part of the field between the nodes that the data see
    (:mod:`calib.parametrizations.aliasing`); a field model without it gets bands without
    that term.
    """

    def correction_field(self) -> "CorrectionField": ...

    def with_grid(self, grid) -> "RefinableFieldModel": ...


@runtime_checkable
class RebuildableModel(Protocol):
    """Optional: a model that can describe itself so a saved result can rebuild it.

    ``spec()`` returns a JSON-able dict with a ``kind`` key understood by
    :func:`calib.models.registry.build_model`; ``rotor_radius`` [m] (or ``None``) lets
    reports use the tip-speed ratio.
    """

    def spec(self) -> dict: ...

    @property
    def rotor_radius(self) -> float | None: ...


from calib.parametrizations.correction_field import CorrectionField  # noqa: E402  (for annotations)
