"""Figures and the self-contained HTML report of a calibration."""

from calib.report.figures import write_figures
from calib.report.html import write_report

__all__ = ["write_figures", "write_report"]
