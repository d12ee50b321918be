"""`livescene stability`: the table, the JSON summary, case selection and the exit status."""

from __future__ import annotations

import json

import pytest

from stages.stability import CASES, Outcome, format_table
from stages.stability.case_context import CaseContext
from stages.stability.case_registry import Case, CaseFailed, run_case
from stages.stability.cli import main

pytestmark = pytest.mark.stability


def test_summary_and_table_for_a_fast_case(tmp_path, capsys):
    out = tmp_path / "summary.json"
    assert main(["--quick", "--case", "rays_missing_the_box", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "case" in printed and "| result | metric" in printed and "rays_missing_the_box | pass" in printed
    summary = json.loads(out.read_text())
    assert summary["counts"]["pass"] == 1 and summary["quick"] is True
    row = summary["cases"][0]
    assert row["name"] == "rays_missing_the_box" and row["values"]["miss_accumulation_max"] < 1e-2


def test_unknown_case_is_rejected(capsys):
    assert main(["--case", "no-such-case"]) == 2
    assert "unknown stability cases" in capsys.readouterr().err


def test_list_names_every_case(capsys):
    assert main(["--list"]) == 0
    printed = capsys.readouterr().out
    assert all(name in printed for name in CASES)


def test_failures_and_crashes_become_rows(tmp_path):
    def failing(ctx):
        raise CaseFailed("weights sum to 1.2")

    def crashing(ctx):
        return 1 / 0

    ctx = CaseContext(tmp_path)
    rows = [run_case(Case("f", "numerics", "x", failing), ctx).to_dict(),
            run_case(Case("c", "numerics", "x", crashing), ctx).to_dict(),
            run_case(Case("p", "numerics", "x", lambda c: Outcome("ok 1.0")), ctx).to_dict()]
    assert [r["result"] for r in rows] == ["fail", "error", "pass"]
    assert "ZeroDivisionError" in rows[1]["detail"]
    table = format_table(rows)
    assert "weights sum to 1.2" in table and "ok 1.0" in table
