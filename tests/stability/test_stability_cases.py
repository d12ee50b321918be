"""Every packaged stability check, run as `livescene stability --quick --workflow <this checkout>` runs it.

One test per case (the case list is collected from the package, so a new check gets its test without an
edit here). A case skipped for want of hardware (no GPU) is a pytest skip with the case's reason; a case
that documents a gap another stage still has to close is an xfail naming the request (see KNOWN_GAPS).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from stages.stability import run_suite

KNOWN_GAPS: dict[str, str] = {}
"""Cases that fail because an owning stage lacks the behaviour; each names where it was asked for."""

CASES = run_suite(collect_only=True).collected
"""name, group, checks and markers of every packaged check (collected, not run)."""


def _params():
    for c in CASES:
        marks = [pytest.mark.stability] + ([pytest.mark.slow] if "slow" in c["markers"] else [])
        if c["name"] in KNOWN_GAPS:
            marks.append(pytest.mark.xfail(reason=KNOWN_GAPS[c["name"]], strict=False))
        yield pytest.param(c["name"], id=c["name"], marks=marks)


@pytest.mark.parametrize("case", list(_params()))
def test_case(case: str, request: pytest.FixtureRequest,
              stability_summary: Callable[[bool], dict[str, Any]]) -> None:
    summary = stability_summary(request.node.get_closest_marker("slow") is not None)
    row = next((r for r in summary["cases"] if r["name"] == case), None)
    assert row is not None, f"{case}: no row in the summary of the run"
    if row["result"] == "skip":
        pytest.skip(row["detail"])
    assert row["result"] == "pass", f"{row['name']}: {row['result']}: {row['detail']}"
    assert row["metric"] and row["metric"] != "-"


def test_every_group_has_cases() -> None:
    assert {c["group"] for c in CASES} == {"numerics", "guards", "bad_input", "interrupted"}
    assert len({c["name"] for c in CASES}) == len(CASES), "two checks share a case name"
