"""The diagnosis (``calib diagnose``; the discrepancy workflow of the documentation): find where the model
and the measurements disagree, localize it on the (α, η) plane, name the missing physical effect, add it
and show the gap shrink.

- :mod:`calib.diagnosis.core`         the five steps (:func:`~calib.diagnosis.core.diagnose`) and their result;
- :mod:`calib.diagnosis.separation`   the measurement that would tell two candidates apart;
- :mod:`calib.diagnosis.fmu`          the candidates of an FMU (its mapped parameters);
- :mod:`calib.diagnosis.in_workflow`  ``[diagnosis]`` inside a ``calib run`` workflow;
- :mod:`calib.diagnosis.command`      the ``calib diagnose`` command.
"""

from calib.diagnosis.core import Diagnosis, DiagnosisSettings, diagnose

__all__ = ["Diagnosis", "DiagnosisSettings", "diagnose"]
