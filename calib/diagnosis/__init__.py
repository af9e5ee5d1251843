"""The diagnosis (``calib diagnose``, ``[diagnosis]`` of a workflow): find where the model
and the measurements disagree, localize it on the (α, η) plane, name the missing physical effect, add it
and show the gap shrink.

- :mod:`calib.diagnosis.core`         the five steps (:func:`~calib.diagnosis.core.diagnose`) and the naming rounds;
- :mod:`calib.diagnosis.settings`     :class:`DiagnosisSettings`;
- :mod:`calib.diagnosis.result`       :class:`Diagnosis` and a candidate's fit;
- :mod:`calib.diagnosis.figures_of_merit`  the gap between measurements and a model, and where it lies;
- :mod:`calib.diagnosis.bem_family`   the candidate effects of the native BEM;
- :mod:`calib.diagnosis.candidate_parameters`  a candidate's parameters: at a bound, stuck at its start;
- :mod:`calib.diagnosis.ranking`      likelihood ratios, BIC weights and pattern agreement;
- :mod:`calib.diagnosis.verdict`      the verdict of a naming round;
- :mod:`calib.diagnosis.separation`   the measurement that would tell two candidates apart;
- :mod:`calib.diagnosis.fmu`          the candidates of an FMU (its mapped parameters);
- :mod:`calib.diagnosis.in_workflow`  ``[diagnosis]`` inside a ``calib run`` workflow;
- :mod:`calib.diagnosis.command`      the ``calib diagnose`` command.
"""

from calib.diagnosis.core import Diagnosis, DiagnosisSettings, diagnose

__all__ = ["Diagnosis", "DiagnosisSettings", "diagnose"]
