"""Small HTML builders shared by the pages (escaping, tables, numbers, the page shell)."""

from __future__ import annotations

import math
from html import escape
from typing import Any

STYLE = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:0 auto;max-width:1200px;padding:0 16px 40px;
color:#222;line-height:1.4}
h1{margin:18px 0 4px}h2{border-bottom:2px solid #ddd;padding-bottom:4px;margin-top:32px}
table{border-collapse:collapse;margin:8px 0;font-size:14px}th,td{border:1px solid #ccc;padding:4px 8px;text-align:left;
vertical-align:top}th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
.missing{color:#8a5a00;background:#fff7e0;border-left:4px solid #e0a800;padding:6px 10px}
.ok{color:#176617}.skip{color:#777}.fail{color:#b00020;font-weight:bold}
figure{display:inline-block;margin:4px;text-align:center;font-size:12px}
figure img{display:block;image-rendering:pixelated;width:192px}
.grid td{padding:2px;text-align:center;font-size:12px}.grid img{display:block;max-width:240px;width:100%}
nav a{margin-right:10px;font-size:14px}
.slider{display:inline-block;margin:10px 16px 20px 0;vertical-align:top}.slider img{width:288px;image-rendering:auto}
.note{color:#555;font-size:13px}
.flag{display:inline-block;color:#8b0000;background:#ffe8e8;border-left:4px solid #d00020;padding:3px 8px;
font-weight:bold}
"""


def fmt(value: Any, digits: int = 3, unit: str = "") -> str:
    """A number for a table cell; None / NaN become an en dash."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int):
        return f"{value:,}{unit}"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}f}{unit}"
    return escape(str(value))


def table(headers: list[str], rows: list[list[Any]], *, cls: str = "") -> str:
    """A table; cells that are str are taken as HTML (callers escape), numbers are formatted."""
    head = "".join(f"<th>{escape(h)}</th>" for h in headers)
    body = []
    for r in rows:
        cells = []
        for c in r:
            if isinstance(c, (int, float)) and not isinstance(c, bool):
                cells.append(f'<td class="num">{fmt(c)}</td>')
            elif c is None:
                cells.append('<td class="num">–</td>')
            else:
                cells.append(f"<td>{c}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f'<table class="{cls}"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>'


def note_list(head: str, items: list[str]) -> str:
    """A note (``head``, HTML) over a bulleted list of ``items`` (HTML each): a stage's warnings on a page."""
    return f'<p class="note">{head}</p><ul>' + "".join(f"<li>{item}</li>" for item in items) + "</ul>"


def missing(text: str) -> str:
    """The notice a section shows when its input is absent (says why)."""
    return f'<p class="missing">{escape(text)}</p>'


def page(title: str, body: str, script: str = "") -> str:
    """A complete, self-contained HTML document."""
    js = f"<script>{script}</script>" if script else ""
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1"><link rel="icon" href="data:,">'
            f"<title>{escape(title)}</title><style>{STYLE}</style></head><body>{body}{js}</body></html>\n")
