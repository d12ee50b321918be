"""The paired verdicts of every scene in one table: the index page's matrix and verdicts.csv."""

from __future__ import annotations

import io
import json

import pandas as pd
import pytest

from stages.report.cli import main as report_main
from stages.report.index_page import build_index, load_summaries
from stages.report.verdict_table import COLUMNS, short_verdict, verdict_matrix_html, verdict_rows, verdicts_csv
from stages.scene import InputError


def _row(baseline: str, metric: str, mean: float | None, ci: list[float] | None, verdict: str,
         flagged: list[str] | None = None) -> dict:
    return {"livescene": "livescene", "baseline": baseline, "metric": metric, "n": 8, "mean_difference": mean,
            "ci95": ci, "verdict": verdict, "rests_on_flagged_run": flagged or [], "statement": verdict, "note": ""}


def _summary(scene: str, objects: list[str], verdict: list[dict]) -> dict:
    return {"scene": scene, "page": f"scenes/{scene}.html", "objects": objects, "frames": 80,
            "registered_fraction": 1.0, "methods": {}, "verdict": verdict, "skipped": [], "job_seconds": 1.0}


SUMMARIES = [
    _summary("office", ["a", "b", "c"], [
        _row("mk-planes", "held_out_psnr", 0.83, [0.08, 1.58], "LiveScene ahead"),
        _row("mk-planes", "locality_outside", -6.2, [-7.0, -5.4], "LiveScene ahead"),
        _row("conerf", "held_out_psnr", 2.1, [1.0, 3.2], "LiveScene ahead", flagged=["conerf"])]),
    _summary("pantry", ["fridge"], [
        _row("mk-planes", "held_out_psnr", -0.75, [-1.18, -0.31], "LiveScene behind"),
        _row("mk-planes", "grounding_iou", 0.0021, [-0.01, 0.014], "no measurable difference (n=8)"),
        _row("mk-planes", "unseen_psnr", None, None, "no paired items")]),
    _summary("alone", ["a"], []),  # LiveScene alone: no verdict, no rows
]


def test_short_verdicts():
    assert [short_verdict(v) for v in ("LiveScene ahead", "LiveScene behind", "no measurable difference (n=16)",
                                       "no paired items")] == ["ahead", "behind", "level", "none"]


def test_rows_are_tidy_and_keep_every_scene_and_metric():
    frame = verdict_rows(SUMMARIES)
    assert list(frame.columns) == COLUMNS and len(frame) == 6
    pantry = frame[frame["scene"] == "pantry"].set_index("metric")
    assert pantry.loc["held_out_psnr", "verdict"] == "behind" and pantry.loc["held_out_psnr", "objects"] == 1
    assert (pantry.loc["held_out_psnr", "ci95_low"], pantry.loc["held_out_psnr", "ci95_high"]) == (-1.18, -0.31)
    assert pantry.loc["grounding_iou", "verdict"] == "level"
    assert pd.isna(pantry.loc["unseen_psnr", "mean_difference"]) and pantry.loc["unseen_psnr", "verdict"] == "none"
    # no paired items, no interval: the CSV leaves it empty rather than inventing [0, 0]
    assert pd.isna(pantry.loc["unseen_psnr", "ci95_low"]) and pd.isna(pantry.loc["unseen_psnr", "ci95_high"])
    assert frame[frame["baseline"] == "conerf"]["rests_on_flagged_run"].tolist() == ["conerf"]


def test_csv_round_trips_exactly():
    frame = verdict_rows(SUMMARIES)
    text = verdicts_csv(frame)
    assert text == verdicts_csv(verdict_rows(SUMMARIES))  # the same summaries give the same bytes
    back = pd.read_csv(io.StringIO(text), keep_default_na=False, na_values=[""])
    assert back["mean_difference"].tolist()[:3] == [0.83, -6.2, 2.1]  # no rounding
    assert back["verdict"].tolist() == frame["verdict"].tolist()


def test_matrix_has_a_row_per_scene_and_baseline_and_a_tally():
    html = verdict_matrix_html(verdict_rows(SUMMARIES))
    matrix, tally = html.split("<table")[1], html.split("<table")[2]
    # rows (office, mk-planes), (office, conerf), (pantry, mk-planes); metric columns in paired.METRICS order
    assert matrix.count("<tr>") == 4
    assert matrix.index("held-out PSNR (dB)") < matrix.index("unseen combinations (dB)") \
        < matrix.index("grounding IoU") < matrix.index("locality (lower is better) (/255)")
    assert '<span class="ok">ahead</span> +0.83 [0.08, 1.58]' in matrix
    assert '<span class="fail">behind</span> -0.75 [-1.18, -0.31]' in matrix
    assert '<span class="skip">level</span> +0.002 [-0.010, 0.014]' in matrix
    assert '<span class="flag">&#9888; conerf</span>' in matrix
    assert "alone" not in matrix  # no verdict, no row
    # mk-planes' held-out PSNR: office ahead, pantry behind
    assert "<td>mk-planes</td><td>held-out PSNR per view</td><td class=\"num\">2</td><td class=\"num\">1</td>" \
           "<td class=\"num\">0</td><td class=\"num\">1</td><td class=\"num\">0</td>" in tally
    # conerf's only verdict rests on a flagged run: it is not a result, so it is counted apart, not as ahead
    assert "<td>conerf</td><td>held-out PSNR per view</td><td class=\"num\">1</td><td class=\"num\">0</td>" \
           "<td class=\"num\">0</td><td class=\"num\">0</td><td class=\"num\">1</td>" in tally


def test_no_verdict_anywhere_says_why():
    html = verdict_matrix_html(verdict_rows([SUMMARIES[2]]))
    assert "No scene has a paired verdict" in html and "<table" not in html


def test_index_cli_writes_the_page_and_the_csv(tmp_path, capsys):
    files = []
    for s in SUMMARIES:
        files.append(tmp_path / f"{s['scene']}.json")
        files[-1].write_text(json.dumps(s))
    out, csv = tmp_path / "reports" / "index.html", tmp_path / "reports" / "verdicts.csv"
    assert report_main(["index", "--summaries", *map(str, files), "--out", str(out), "--csv", str(csv)]) == 0
    page = out.read_text()
    assert "Verdicts across scenes" in page and page.count("<h2>") == 2
    assert page.index("Verdicts across scenes") < page.index('href="scenes/pantry.html"')
    # the scenes table counts each baseline's verdicts: office vs mk-planes ahead twice, pantry behind once
    assert "vs mk-planes: 2 ahead, 0 level, 0 behind" in page and "vs mk-planes: 0 ahead, 1 level, 1 behind" in page
    assert csv.read_text() == verdicts_csv(verdict_rows(SUMMARIES))
    assert build_index(SUMMARIES) == page


def test_index_names_an_unreadable_summary(tmp_path):
    bad = tmp_path / "summary.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match="unreadable scene summary"):
        load_summaries([bad])


def test_the_tally_adds_up_with_scenes_without_paired_items():
    import re

    tally = verdict_matrix_html(verdict_rows(SUMMARIES)).split("<table")[2]
    assert "no paired items" in tally
    # pantry has no unseen combination: counted, and said so, not left out of ahead + level + behind
    assert "<td>mk-planes</td><td>unseen-combination PSNR per (view, state vector)</td><td class=\"num\">1</td>" + \
           "<td class=\"num\">0</td>" * 4 + "<td class=\"num\">1</td>" in tally
    for row in tally.split("<tr>")[2:]:
        scenes, ahead, level, behind, flagged, none = map(int, re.findall(r'class="num">(\d+)<', row))
        assert scenes == ahead + level + behind + flagged + none, row


def test_pages_of_earlier_runs_are_listed_apart_and_outside_the_verdicts(tmp_path):
    files = {}
    for s in SUMMARIES:
        files[s["scene"]] = tmp_path / f"{s['scene']}.json"
        files[s["scene"]].write_text(json.dumps({**s, "built": "2026-11-28 21:04 UTC"}))
    out, csv = tmp_path / "reports" / "index.html", tmp_path / "reports" / "verdicts.csv"
    assert report_main(["index", "--summaries", str(files["office"]), "--earlier", str(files["pantry"]),
                        "--out", str(out), "--csv", str(csv)]) == 0
    page = out.read_text()
    current, earlier = page.split("<h2>Pages from earlier runs</h2>")
    assert 'href="scenes/pantry.html"' in earlier and "2026-11-28 21:04 UTC" in earlier
    assert "pantry" not in current  # not in the matrix, the tally or the scenes table of this run
    assert "settings of that run, which may differ" in earlier and "--config only=pantry" in earlier
    assert set(pd.read_csv(csv)["scene"]) == {"office"}
