"""Reports: Markdown with publication-quality PNG figures (:func:`write_report` for a fit)."""

from coordinator.report.markdown import write_report

__all__ = ["write_report"]
