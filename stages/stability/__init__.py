"""Numerical stability on stiff and extreme cases, bad input, and interrupted runs.

The checks are plain pytest tests in ``checks/`` (one module per group) and ship with the package,
with the capture presets they render (``captures/``), so that ``livescene stability`` runs them on an
installed copy as in this repository: :func:`run_suite` runs them through ``pytest.main`` with the
:class:`SummaryCollector` plugin, which writes the summary the report includes. Nothing here reads the
repository's layout: the one check that dry-runs the workflow copies the checkout given with
``--workflow``. See docs/stability.md.

Importing this package loads pytest but not torch: the checks import the model code when pytest
collects them.
"""

from .collector import GROUPS, SUMMARY_FORMAT, CaseResult, Outcome, SummaryCollector
from .suite import CAPTURES_DIR, CHECKS_DIR, SuiteRun, format_markdown, format_table, pytest_args, run_suite

__all__ = [
    "CAPTURES_DIR",
    "CHECKS_DIR",
    "GROUPS",
    "SUMMARY_FORMAT",
    "CaseResult",
    "Outcome",
    "SuiteRun",
    "SummaryCollector",
    "format_markdown",
    "format_table",
    "pytest_args",
    "run_suite",
]
