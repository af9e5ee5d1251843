"""Campaign design (``calib design``): which operating points and sensors to measure, before the campaign
is run. :func:`design` on a :class:`DesignProblem` of :func:`problem_from_workflow`."""

from calib.design.core import CRITERIA, DesignResult, design
from calib.design.problem import DesignProblem, problem_from_workflow

__all__ = ["CRITERIA", "DesignProblem", "DesignResult", "design", "problem_from_workflow"]
