"""The packaged stability checks, run in quick mode through the same pytest API as `livescene stability`.

Each outer test reads its case's row from a summary; the summaries come from two runs made on first use,
one of the fast cases and one of the `slow` ones (interrupted runs start real processes), each limited to
the cases this session selected (`-k`, `-m 'not slow'`), with this checkout as the `--workflow`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from stages.stability import run_suite

REPO = Path(__file__).resolve().parents[2]
"""This checkout: the workflow the check `bad_workflow_config_wrong_type` dry-runs."""


def _selected_cases(session: pytest.Session, slow: bool) -> list[str]:
    """Case names of this session's selected `test_case` items of one speed."""
    names = []
    for item in session.items:
        callspec = getattr(item, "callspec", None)
        is_case = getattr(item, "originalname", "") == "test_case" and callspec is not None
        if is_case and (item.get_closest_marker("slow") is not None) == slow:
            names.append(callspec.params["case"])
    return names


@pytest.fixture(scope="session")
def stability_summary(request: pytest.FixtureRequest,
                      tmp_path_factory: pytest.TempPathFactory) -> Callable[[bool], dict[str, Any]]:
    """``summary(slow)``: the quick summary of the selected fast (or slow) cases, run once per session."""
    runs: dict[bool, dict[str, Any]] = {}

    def summary(slow: bool) -> dict[str, Any]:
        if slow not in runs:
            cases = _selected_cases(request.session, slow)
            run = run_suite(cases, quick=True, threads=1, workflow=REPO,
                            workdir=tmp_path_factory.mktemp("slow" if slow else "fast"))
            assert run.exit_code in (0, 1) and not run.error, f"the checks did not run: {run.exit_code} {run.error}"
            runs[slow] = run.summary
        return runs[slow]

    return summary
