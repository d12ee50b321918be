"""The index page: one row per scene with its headline numbers and a link to its page."""

from __future__ import annotations

import json
from html import escape
from pathlib import Path

from stages.scene import InputError

from .html_parts import fmt, page, table


def build_index(summary_files: list[str | Path]) -> str:
    """HTML of reports/index.html from the scenes' summary.json files."""
    rows = []
    for path in summary_files:
        path = Path(path)
        try:
            s = json.loads(path.read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise InputError(path, f"unreadable scene summary ({exc})", "re-run the scene's report rule") from exc
        methods = "<br>".join(f"{escape(name)}: PSNR {fmt(v.get('psnr'), 2)} dB, SSIM {fmt(v.get('ssim'), 3)}, "
                              f"{fmt(v.get('train_seconds'), 0)} s training" for name, v in s["methods"].items())
        rows.append([f'<a href="{escape(s["page"])}">{escape(s["scene"])}</a>',
                     escape(", ".join(s.get("objects", []))), s.get("frames"), s.get("registered_fraction"),
                     methods or "–", escape(", ".join(s.get("skipped", [])) or "none"), s.get("job_seconds")])
    body = ("<h1>LiveScene reports</h1><p>One page per scene of the scene sheet; each opens offline.</p>"
            + table(["scene", "objects", "frames", "poses registered", "methods (held-out)", "rules skipped",
                     "job seconds"], rows))
    return page("LiveScene reports", body)
