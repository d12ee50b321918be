"""`livescene stability`: the table, the JSON summary, case selection, the exit status, the rows the collector
makes of failures, crashes and skips, and what the package carries so that it runs on an installed copy."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml

from stages.stability import CAPTURES_DIR, SummaryCollector, format_table
from stages.stability.cli import main

pytestmark = pytest.mark.stability

REPO = Path(__file__).resolve().parents[2]


def test_summary_and_table_for_a_fast_case(tmp_path, capsys):
    """One passing case and the one that skips without --workflow (a skip is no failure: exit status 0)."""
    out = tmp_path / "summary.json"
    assert main(["--quick", "--case", "rays_missing_the_box", "--case", "bad_workflow_config_wrong_type",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "case" in printed and "| result | metric" in printed and "rays_missing_the_box           | pass" in printed
    assert "bad_workflow_config_wrong_type | skip   | no workflow checkout to dry-run" in printed
    summary = json.loads(out.read_text())
    assert list(summary) == ["format", "quick", "counts", "seconds", "machine", "cases"]
    assert summary["format"] == 1 and summary["quick"] is True
    assert summary["counts"] == {"pass": 1, "fail": 0, "error": 0, "skip": 1}
    assert set(summary["machine"]) == {"cpu", "logical_cores", "python", "torch", "torch_cpu_capability", "cuda",
                                       "threads", "omp_wait_policy"}
    row, skipped = summary["cases"]  # in the table's order: numerics before bad_input
    assert list(row) == ["name", "group", "result", "metric", "checks", "seconds", "values", "detail"]
    assert row["name"] == "rays_missing_the_box" and row["group"] == "numerics"
    assert row["values"]["miss_accumulation_max"] < 1e-2 and row["checks"].startswith("rays that miss")
    assert skipped["name"] == "bad_workflow_config_wrong_type" and skipped["group"] == "bad_input"
    assert skipped["metric"] == "-" and "--workflow PATH" in skipped["detail"]


def test_unknown_case_is_rejected(capsys):
    assert main(["--case", "no-such-case"]) == 2
    assert "unknown stability cases" in capsys.readouterr().err


def test_list_names_every_case(capsys):
    assert main(["--list"]) == 0
    printed = capsys.readouterr().out
    for name in ("states_exactly_0_and_1", "units_0.001x", "autocast_cpu_fp16", "bad_workflow_config_wrong_type",
                 "snakemake_interrupt_reruns_incomplete"):
        assert f"{name} [" in printed


def test_failures_and_crashes_become_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("PYTEST_DISABLE_PLUGIN_AUTOLOAD", "1")  # as run_suite does; some installed plugins are slow
    (tmp_path / "conftest.py").write_text(
        "import pytest\nfrom stages.stability.collector import OUTCOME, Outcome\n\n@pytest.fixture\n"
        "def outcome(request):\n    o = Outcome()\n    request.node.stash[OUTCOME] = o\n    return o\n")
    (tmp_path / "test_rows.py").write_text(
        "import pytest\n\npytestmark = pytest.mark.stability_group('numerics')\n\n"
        "def test_f():\n    w = 1.2\n    assert w <= 1.0, f'weights sum to {w}'\n\n"
        "def test_c():\n    1 / 0\n\n"
        "def test_s():\n    pytest.skip('no GPU here')\n\n"
        "@pytest.mark.parametrize('x', [pytest.param(1, id='0.5x')])\n"
        "def test_p(outcome, x):\n    '''what p checks'''\n    outcome.record('ok 1.0', {'x': x})\n")
    collector = SummaryCollector()
    pytest.main([str(tmp_path), "-q", "-p", "no:cacheprovider", "-W", "ignore::pytest.PytestUnknownMarkWarning"],
                plugins=[collector])
    rows = collector.summary()["cases"]
    assert [(r["name"], r["result"]) for r in rows] == [("f", "fail"), ("c", "error"), ("s", "skip"),
                                                       ("p_0.5x", "pass")]
    assert rows[0]["detail"] == "weights sum to 1.2"  # the message, without pytest's introspection
    assert "ZeroDivisionError" in rows[1]["detail"] and rows[2]["detail"] == "no GPU here"
    assert rows[3]["metric"] == "ok 1.0" and rows[3]["values"] == {"x": 1} and rows[3]["checks"] == "what p checks"
    assert all(r["group"] == "numerics" for r in rows)
    table = format_table(rows)
    assert "weights sum to 1.2" in table and "ok 1.0" in table and "ZeroDivisionError" in table


def test_packaged_capture_presets_match_the_workflow():
    """The checks render the package's capture presets, the workflow's config/captures (an installed copy has no
    config/)."""
    for preset in sorted(CAPTURES_DIR.glob("*.yaml")):
        assert yaml.safe_load(preset.read_text()) == yaml.safe_load((REPO / "config" / "captures" /
                                                                      preset.name).read_text()), preset.name
    assert {p.stem for p in CAPTURES_DIR.glob("*.yaml")} >= {"demo", "stiff", "stress", "extreme", "tiny"}
