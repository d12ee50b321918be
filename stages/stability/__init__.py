"""Numerical stability on stiff and extreme cases, bad input, and interrupted runs.

``livescene stability`` and ``tests/stability`` run the same registered cases
(:data:`CASES`); see docs/stability.md for what each one checks.
"""

from .case_context import CaseContext
from .case_registry import CASES, Case, CaseFailed, CaseResult, CaseSkipped, Outcome, require, run_case
from .suite import format_markdown, format_table, run_suite, select

__all__ = [
    "CASES",
    "Case",
    "CaseContext",
    "CaseFailed",
    "CaseResult",
    "CaseSkipped",
    "Outcome",
    "format_markdown",
    "format_table",
    "require",
    "run_case",
    "run_suite",
    "select",
]
