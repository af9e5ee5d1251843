"""Parametrizations a forward model may offer the calibrator (docs/theory.md, Architecture and Correction field).

A parametrization knows what a block of the parameter vector *means*: where correction
nodes sit on the (α, η) plane, how to map them to a field, which bounds keep the polars
physical, and how to draw eigenshapes and bands. The calibrator asks a model for it
when the model declares one (``capabilities.correction_field``, :class:`calib.models.base.Capabilities`); a model without one
(e.g. an FMU with a few scalar tuning parameters) still gets everything generic.
"""

from calib.parametrizations.correction_field import (CorrectionField, NodeLayout, eigenshapes, field_basis,
                                                     node_layout)

__all__ = ["CorrectionField", "NodeLayout", "eigenshapes", "field_basis", "node_layout"]
