"""The index page: the paired verdicts of every scene in one matrix (``verdict_table.py``), then one row per
scene with its headline numbers and a link to its page."""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

import pandas as pd

from stages.scene import InputError

from .html_parts import fmt, page, table
from .verdict_table import WORDS, verdict_counts, verdict_matrix_html, verdict_rows


def load_summaries(summary_files: list[str | Path]) -> list[dict]:
    """The scenes' summary.json files (``scene_page.scene_summary``), in the order given."""
    out = []
    for path in summary_files:
        path = Path(path)
        try:
            out.append(json.loads(path.read_text()))
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(path, f"unreadable scene summary ({exc})", "re-run the scene's report rule") from exc
    return out


def build_index(summaries: list[dict], pending: list[str] | None = None, earlier: list[dict] | None = None) -> str:
    """HTML of the index page from the summaries of the scenes this run built (each links its page by its "page");
    ``earlier`` are pages of the sheet's other scenes that an earlier run wrote (``--config only=...``): listed
    apart, outside the verdicts and their tally, as their settings may differ; ``pending`` names the sheet's
    scenes with no page at all."""
    verdicts = verdict_rows(summaries)
    rows = [_scene_row(s, verdicts) for s in summaries]
    waiting = ""
    if pending:
        names = ", ".join(escape(n) for n in pending)
        waiting = (f"<p>Scenes of the sheet without a page (not built by this run nor an earlier one; a scene whose "
                   f"jobs failed stays here until they succeed: Snakemake's error names the failing job's log): "
                   f"{names}. Build one with <code>snakemake --cores 2 --config only={escape(pending[0])}</code>."
                   "</p>")
    before = ""
    if earlier:
        old_verdicts = verdict_rows(earlier)
        before = ("<h2>Pages from earlier runs</h2><p>Scenes of the sheet this run did not build (it was restricted "
                  "with <code>--config only=...</code>): their pages as an earlier run left them, built with the "
                  "settings of that run, which may differ from this one's. They are not in the verdicts above nor "
                  "in <code>verdicts.csv</code>; rebuild one with <code>snakemake --cores 2 --config "
                  f"only={escape(earlier[0]['scene'])}</code>.</p>"
                  + table([*SCENE_HEADERS, "page built"],
                          [[*_scene_row(s, old_verdicts), escape(str(s.get("built") or "–"))] for s in earlier]))
    # the verdicts first: over a sheet of rooms they are what the index is read for; the scenes table below
    # counts them per baseline and links each scene's page
    body = ("<h1>LiveScene reports</h1><p>One page per scene of the scene sheet; each opens offline. A flagged run "
            "(&#9888;) is under its trust floors: its numbers are not results.</p>"
            + "<h2>Verdicts across scenes</h2>" + verdict_matrix_html(verdicts)
            + "<h2>Scenes</h2>" + table(SCENE_HEADERS, rows) + waiting + before)
    return page("LiveScene reports", body)


SCENE_HEADERS = ["scene", "objects", "frames", "poses registered", "methods (held-out)",
                 "LiveScene vs baselines (paired metrics)", "rules skipped", "job seconds"]


def _scene_row(s: dict, verdicts: pd.DataFrame) -> list:
    """One scene's row of the scenes table: its link, headline numbers and verdict counts."""
    methods = "<br>".join(f"{escape(name)}: PSNR {fmt(v.get('psnr'), 2)} dB, SSIM {fmt(v.get('ssim'), 3)}, "
                          f"{fmt(v.get('steps'))} steps, {fmt(v.get('train_seconds'), 0)} s training"
                          + _flag(v.get("trust"))
                          for name, v in s["methods"].items())
    registered = s.get("registered_fraction")
    seconds = s.get("job_seconds")
    return [f'<a href="{escape(s["page"])}">{escape(s["scene"])}</a>', escape(", ".join(s.get("objects", []))),
            s.get("frames"), f"{registered:.0%}" if isinstance(registered, (int, float)) else "–",
            methods or "–", _verdicts(verdicts[verdicts["scene"] == s.get("scene")]) if not verdicts.empty else "–",
            escape(", ".join(s.get("skipped", [])) or "none"),
            fmt(float(seconds), 0) if isinstance(seconds, (int, float)) else "–"]


def _flag(trust: dict | None) -> str:
    if not trust or not trust.get("flagged"):
        return ""
    return f' <span class="flag">&#9888; {escape(str(trust.get("label", "flagged")))}</span>'


def _verdicts(scene: pd.DataFrame) -> str:
    """Per baseline, how many paired metrics LiveScene is ahead, level or behind on (the matrix above has each);
    a count resting on a flagged run says so."""
    lines = []
    for baseline, group in scene.groupby("baseline", sort=False):
        line = f"vs {escape(str(baseline))}: " + ", ".join(
            f"{n} {word}" for n, word in zip(verdict_counts(group), WORDS, strict=True))
        flagged = sorted({name for names in group["rests_on_flagged_run"] for name in names.split(";") if name})
        if flagged:
            line += f' <span class="flag">&#9888; rests on flagged {escape(", ".join(flagged))}</span>'
        lines.append(line)
    return "<br>".join(lines) or "–"
