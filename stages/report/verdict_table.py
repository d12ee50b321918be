"""The paired verdicts of every scene in one table: LiveScene against each baseline, metric by metric.

Each scene page ends in its own verdict (``paired.py``); a user who runs the workflow over a sheet of rooms
wants to see across them where LiveScene is ahead, level or behind without opening every page. The index
page shows the matrix (a row per scene and baseline, a column per paired metric) and a tally per baseline and
metric; ``verdicts.csv`` beside it holds the same rows in tidy form for pandas (docs/workflow.md, "The report").
"""

from __future__ import annotations

from html import escape

import pandas as pd

from .html_parts import fmt, table
from .paired import METRICS

COLUMNS = ["scene", "objects", "baseline", "metric", "n", "mean_difference", "ci95_low", "ci95_high", "verdict",
           "rests_on_flagged_run"]
"""verdicts.csv: one row per (scene, baseline, paired metric); ``verdict`` is ahead / behind / level / none."""

SHORT = {"LiveScene ahead": "ahead", "LiveScene behind": "behind", "no paired items": "none"}
"""paired.verdict's sentences in one word; "no measurable difference (n=...)" reads "level"."""

UNITS = {spec.key: spec.unit for spec in METRICS}
LABELS = {spec.key: spec.label for spec in METRICS}
HEADERS = {"held_out_psnr": "held-out PSNR", "held_out_psnr_objects": "held-out, object pixels",
           "held_out_psnr_static": "held-out, static pixels", "held_out_psnr_nominal": "held-out, nominal exposure",
           "unseen_psnr": "unseen combinations", "grounding_iou": "grounding IoU",
           "locality_outside": "locality (lower is better)"}
"""The matrix's column heads (the CSV keeps ``paired.METRICS``' keys)."""


def short_verdict(sentence: str) -> str:
    return SHORT.get(sentence, "level" if sentence.startswith("no measurable difference") else sentence)


WORDS = ("ahead", "level", "behind")
"""The verdicts counted in the tally and in the index's scenes table ("none" is not counted)."""


def verdict_counts(group: pd.DataFrame) -> list[int]:
    """How many of ``group``'s rows read ahead, level and behind (``WORDS`` order)."""
    counts = group["verdict"].value_counts()
    return [int(counts.get(word, 0)) for word in WORDS]


def verdict_rows(summaries: list[dict]) -> pd.DataFrame:
    """The tidy table of every scene summary's paired verdict (scenes in the order given)."""
    rows = []
    for s in summaries:
        for r in s.get("verdict") or []:
            ci = r.get("ci95") or [None, None]
            rows.append({"scene": s.get("scene"), "objects": len(s.get("objects") or []),
                         "baseline": r.get("baseline"), "metric": r.get("metric"), "n": r.get("n"),
                         "mean_difference": r.get("mean_difference"), "ci95_low": ci[0], "ci95_high": ci[1],
                         "verdict": short_verdict(str(r.get("verdict"))),
                         "rests_on_flagged_run": ";".join(r.get("rests_on_flagged_run") or [])})
    return pd.DataFrame(rows, columns=COLUMNS)


def verdicts_csv(frame: pd.DataFrame) -> str:
    # repr-exact floats: the CSV of two identical runs is byte-identical, and nothing is rounded away
    return frame.to_csv(index=False, lineterminator="\n")


def _cell(row: pd.Series) -> str:
    cls = {"ahead": "ok", "behind": "fail"}.get(row["verdict"], "skip")
    unit = UNITS.get(row["metric"], "")
    text = f'<span class="{cls}">{escape(row["verdict"])}</span>'
    if pd.notna(row["mean_difference"]):
        digits = 2 if unit in ("dB", "/255") else 3
        text += f' {float(row["mean_difference"]):+.{digits}f}'
        if pd.notna(row["ci95_low"]) and pd.notna(row["ci95_high"]):
            text += f' [{fmt(float(row["ci95_low"]), digits)}, {fmt(float(row["ci95_high"]), digits)}]'
    if row["rests_on_flagged_run"]:
        text += f'<br><span class="flag">&#9888; {escape(row["rests_on_flagged_run"].replace(";", ", "))}</span>'
    return text


def verdict_matrix_html(frame: pd.DataFrame) -> str:
    """The matrix and the tally, or a line saying that no scene has a verdict."""
    if frame.empty:
        return ("<p>No scene has a paired verdict: each needs LiveScene and at least one baseline evaluated "
                "(the sheet's <code>methods</code>).</p>")
    metrics = [spec.key for spec in METRICS if spec.key in set(frame["metric"])]
    rows = []
    for (scene, baseline), group in frame.groupby(["scene", "baseline"], sort=False):
        cells = {r["metric"]: _cell(r) for _, r in group.iterrows()}
        rows.append([escape(str(scene)), int(group["objects"].iloc[0]), escape(str(baseline))]
                    + [cells.get(m, "–") for m in metrics])
    headers = ["scene", "objects", "baseline"] + [HEADERS.get(m, m) + (f" ({UNITS[m]})" if UNITS.get(m) else "")
                                                  for m in metrics]
    tally = []
    for (baseline, metric), group in frame.groupby(["baseline", "metric"], sort=False):
        # a verdict that rests on a run under its trust floors is not a result: counted apart, not ranked
        trusted = group[group["rests_on_flagged_run"].fillna("") == ""]
        counts = verdict_counts(trusted)
        tally.append([escape(str(baseline)), escape(LABELS.get(metric, metric)), len(group), *counts,
                      len(group) - len(trusted), len(trusted) - sum(counts)])
    return ("<p>LiveScene minus each baseline on the same items, per scene: the verdict, the mean difference and "
            "its 95% interval (ahead or behind only when the interval excludes 0; locality is lower-is-better, "
            "so there a negative difference is ahead). Each scene page says what its items are.</p>"
            + table(headers, rows)
            + "<p>Across the scenes:</p>"
            + table(["baseline", "paired metric", "scenes", "ahead", "level", "behind",
                     "on a flagged run (not counted)", "no paired items (e.g. no unseen combination)"], tally))
