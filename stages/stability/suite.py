"""Run the packaged stability checks through pytest's API and turn their rows into the table and the summary.

The checks live in ``stages/stability/checks`` (plain pytest tests) and ship with the package, so
``livescene stability`` works the same in this repository and on an installed copy: :func:`run_suite`
calls ``pytest.main`` on that folder with the package's own ``pytest.ini`` (no configuration of the
current folder or auto-loaded plugin changes what runs) and the :class:`SummaryCollector` plugin, which
builds the JSON summary the report reads.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

import pytest

from stages.scene.atomic_io import scratch_folder

from .collector import GROUPS, SUMMARY_FORMAT, CaseResult, SummaryCollector

PACKAGE = Path(__file__).resolve().parent
CHECKS_DIR = PACKAGE / "checks"
"""The test package ``livescene stability`` runs."""
CAPTURES_DIR = PACKAGE / "captures"
"""Capture presets the checks render (package data; in a checkout a link to the workflow's config/captures)."""

__all__ = ["CAPTURES_DIR", "CHECKS_DIR", "GROUPS", "SUMMARY_FORMAT", "SuiteRun", "format_markdown", "format_table",
           "pytest_args", "run_suite"]


@dataclass
class SuiteRun:
    """What one pytest run of the checks gave."""

    summary: dict[str, Any]
    """The JSON summary (``SummaryCollector.summary``)."""
    exit_code: int
    """pytest's exit status (0 all passed, 1 some failed, 2 interrupted, 4 usage error, 5 nothing collected)."""
    error: str = ""
    """Why nothing ran (an unknown case name); empty otherwise."""
    collected: list[dict[str, Any]] = field(default_factory=list)
    """The selected cases in run order: name, group, checks, nodeid, markers."""


def pytest_args(*, quick: bool = False, threads: int = 1, workdir: Path | None = None, workflow: Path | None = None,
                captures: Path | None = None, paths: list[Path] | None = None, collect_only: bool = False,
                extra: list[str] | None = None) -> list[str]:
    """The pytest command line of a run: the checks folder, its ini file, and the ``--stability-*`` options."""
    args = [str(p) for p in (paths or [CHECKS_DIR])]
    args += ["-c", str(CHECKS_DIR / "pytest.ini"), "--stability-threads", str(threads)]
    if quick:
        args.append("--stability-quick")
    for option, value in (("--stability-workdir", workdir), ("--stability-workflow", workflow),
                          ("--stability-captures", captures)):
        if value is not None:
            args += [option, str(Path(value).resolve())]
    args += ["--collect-only", "-q"] if collect_only else ["-v", "--tb=short"]
    return args + list(extra or [])


def run_suite(cases: list[str] | None = None, groups: list[str] | None = None, *, quick: bool = False,
              workdir: Path | None = None, threads: int = 1, workflow: Path | None = None,
              captures: Path | None = None, collect_only: bool = False,
              on_result: Callable[[CaseResult], None] | None = None, paths: list[Path] | None = None,
              extra: list[str] | None = None) -> SuiteRun:
    """Run the selected checks (all by default) in this process; pytest's own output goes to stderr.

    ``cases`` are exact case names and ``groups`` group names; ``workflow`` (a checkout holding Snakefile,
    workflow/ and config/) enables the check that runs the workflow; ``captures`` replaces the packaged
    capture presets; ``paths``/``extra`` are for tests of this function (other test folders, pytest options).
    """
    collector = SummaryCollector(cases, groups, quick=quick, threads=threads, on_result=on_result)
    with contextlib.ExitStack() as stack:
        if workdir is None and not collect_only:  # scratch files go with the run, as pytest's own would not
            workdir = stack.enter_context(scratch_folder("livescene-stability-"))
        args = pytest_args(quick=quick, threads=threads, workdir=workdir, workflow=workflow, captures=captures,
                           paths=paths, collect_only=collect_only, extra=extra)
        # stdout carries the table: pytest's progress and tracebacks go to stderr (the workflow's log)
        stack.enter_context(contextlib.redirect_stdout(sys.stderr))
        # plugins installed beside pytest (auto-loaded through entry points) and PYTEST_ADDOPTS would change what
        # runs, in which order and with which options; the checks need neither (the environment is put back after)
        stack.enter_context(mock.patch.dict(os.environ, {"PYTEST_DISABLE_PLUGIN_AUTOLOAD": "1"}))
        os.environ.pop("PYTEST_ADDOPTS", None)
        code = int(pytest.main(args, plugins=[collector]))
    return SuiteRun(collector.summary(), code, collector.error, collector.collected)


def _metric_or_reason(row: dict[str, Any]) -> str:
    """A row's metric when it passed, else the last line of why not."""
    if row["result"] == "pass":
        return row["metric"]
    return row["detail"].splitlines()[-1] if row["detail"] else "-"


def format_table(rows: list[dict[str, Any]], width: int = 100) -> str:
    """``case | result | metric`` as a plain-text table (the metric is cut to ``width`` characters)."""
    name_w = max([len("case"), *(len(r["name"]) for r in rows)])
    lines = [f"{'case'.ljust(name_w)} | result | metric", f"{'-' * name_w}-|--------|-{'-' * 40}"]
    for r in rows:
        text = _metric_or_reason(r)
        if len(text) > width:
            text = text[: width - 3] + "..."
        lines.append(f"{r['name'].ljust(name_w)} | {r['result'].ljust(6)} | {text}")
    return "\n".join(lines)


def format_markdown(rows: list[dict[str, Any]]) -> str:
    """The same table in Markdown (docs/stability.md, the report): case | group | result | metric or reason."""
    lines = ["| case | group | result | metric (pass) or reason |", "|---|---|---|---|"]
    for r in rows:
        text = _metric_or_reason(r)
        lines.append(f"| {r['name']} | {r['group']} | {r['result']} | {text.replace('|', '/')} |")
    return "\n".join(lines)
