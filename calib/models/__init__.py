"""The adapter layer: the ForwardModel contract and its implementations."""

from calib.models.base import Channel, Evaluation, ForwardModel, OperatingConditions, Parameter
from calib.types import Status, nominal_vector

__all__ = ["Channel", "Evaluation", "ForwardModel", "OperatingConditions", "Parameter", "Status",
           "nominal_vector"]
