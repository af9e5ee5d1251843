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
    """The adapter contract (DESIGN §2.1)."""

    @property
    def parameters(self) -> tuple[Parameter, ...]: ...

    @property
    def channels(self) -> tuple[Channel, ...]: ...

    def evaluate(self, p: np.ndarray, conditions: OperatingConditions) -> Evaluation: ...

    def jacobian(self, p: np.ndarray, conditions: OperatingConditions) -> tuple[Evaluation, np.ndarray]: ...
