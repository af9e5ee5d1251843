"""TOML workflows: ``calib run FILE --out DIR``.

A workflow names a rotor and a correction grid, gets measurements (a CSV file, or
synthetic ones from a *truth* model with seeded noise), and runs one or more
calibration *stages* (e.g. hub loads only, then hub plus blade loads). It writes, per
stage, the result (``result.json`` + ``result.npz``) and the figures, and one
self-contained ``report.html`` that collects them. The schema is documented in
``workflows/README.md``; unknown keys and wrong types are rejected with the file and the
key in the message. :func:`load_workflow` returns a typed, frozen :class:`Workflow`.
"""

from calib.workflow.run import add_run_arguments, main, run_from_args, run_workflow
from calib.workflow.schema import (MODEL_KEYS, SCHEMA, Workflow, check_section, load_workflow, tables_required,
                                   workflow_from_table)
from calib.workflow.sections import CALIBRATION_KEYS
from calib.workflow.setup import (StageOutcome, WorkflowSetup, synthetic_conditions, measurements_of, prepare,
                                  run_inputs)
from calib.workflow.truth import smooth_field, truth_checks, truth_model

__all__ = ["CALIBRATION_KEYS", "MODEL_KEYS", "SCHEMA", "StageOutcome", "Workflow", "WorkflowSetup",
           "add_run_arguments", "check_section", "load_workflow", "main", "measurements_of", "prepare",
           "run_from_args", "run_inputs", "run_workflow", "smooth_field", "synthetic_conditions", "tables_required",
           "truth_checks", "truth_model", "workflow_from_table"]
