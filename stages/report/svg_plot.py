"""Line plots as inline SVG (matplotlib is not a dependency and the page must work offline)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from html import escape

PALETTE = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2"]


@dataclass
class Series:
    """One line of a plot."""

    label: str
    """Legend text."""
    x: list[float]
    """Abscissae (same length as y)."""
    y: list[float]
    """Ordinates; non-finite values are dropped."""


def nice_ticks(lo: float, hi: float, count: int = 5) -> list[float]:
    """Round tick values covering [lo, hi] (1, 2, 5 x 10^k steps)."""
    if not math.isfinite(lo) or not math.isfinite(hi):
        return []
    if hi <= lo:
        hi = lo + 1.0
    raw = (hi - lo) / max(count, 1)
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 5, 10) if m * mag >= raw)
    first = math.floor(lo / step) * step
    ticks, t = [], first
    while t <= hi + step * 1e-9:
        if t >= lo - step * 1e-9:
            ticks.append(round(t, 10))
        t += step
    return ticks


def _fmt(v: float) -> str:
    return f"{v:g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.1e}"


def line_plot_svg(series: list[Series], *, x_label: str, y_label: str, title: str = "",
                  width: int = 640, height: int = 360) -> str:
    """An SVG element with axes, ticks, one polyline + markers per series and a legend."""
    pts = [(x, y) for s in series for x, y in zip(s.x, s.y, strict=False) if math.isfinite(x) and math.isfinite(y)]
    if not pts:
        return f'<p class="missing">No data to plot for {escape(title or y_label)}.</p>'
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    x_lo, x_hi = min(0.0, min(xs)), max(xs)
    y_lo, y_hi = min(ys), max(ys)
    pad = (y_hi - y_lo) * 0.08 or 1.0
    y_lo, y_hi = y_lo - pad, y_hi + pad
    xt, yt = nice_ticks(x_lo, x_hi), nice_ticks(y_lo, y_hi)  # ticks lie inside [lo, hi]: the axes end at the data
    left, right, top, bottom = 64, 150, 34, 48
    pw, ph = width - left - right, height - top - bottom

    def sx(v: float) -> float:
        return left + (v - x_lo) / ((x_hi - x_lo) or 1.0) * pw

    def sy(v: float) -> float:
        return top + ph - (v - y_lo) / ((y_hi - y_lo) or 1.0) * ph

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="{width}" '
             f'height="{height}" role="img" aria-label="{escape(title or y_label)}" class="plot">',
             f'<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="#fff" stroke="#999"/>']
    if title:
        parts.append(f'<text x="{left + pw / 2}" y="20" text-anchor="middle" font-weight="bold">{escape(title)}</text>')
    for t in xt:
        parts.append(f'<line x1="{sx(t):.1f}" x2="{sx(t):.1f}" y1="{top}" y2="{top + ph}" stroke="#eee"/>'
                     f'<text x="{sx(t):.1f}" y="{top + ph + 16}" text-anchor="middle" font-size="11">{_fmt(t)}</text>')
    for t in yt:
        parts.append(f'<line x1="{left}" x2="{left + pw}" y1="{sy(t):.1f}" y2="{sy(t):.1f}" stroke="#eee"/>'
                     f'<text x="{left - 6}" y="{sy(t) + 4:.1f}" text-anchor="end" font-size="11">{_fmt(t)}</text>')
    parts.append(f'<text x="{left + pw / 2}" y="{height - 8}" text-anchor="middle" font-size="12">'
                 f'{escape(x_label)}</text>')
    parts.append(f'<text transform="translate(14 {top + ph / 2}) rotate(-90)" text-anchor="middle" font-size="12">'
                 f'{escape(y_label)}</text>')
    for i, s in enumerate(series):
        colour = PALETTE[i % len(PALETTE)]
        line = [(sx(x), sy(y)) for x, y in zip(s.x, s.y, strict=False) if math.isfinite(x) and math.isfinite(y)]
        if not line:
            continue
        coords = " ".join(f"{a:.1f},{b:.1f}" for a, b in line)
        parts.append(f'<polyline fill="none" stroke="{colour}" stroke-width="2" points="{coords}">'
                     f'<title>{escape(s.label)}</title></polyline>')
        parts.extend(f'<circle cx="{a:.1f}" cy="{b:.1f}" r="2.5" fill="{colour}"/>' for a, b in line)
        ly = top + 14 + 18 * i
        parts.append(f'<line x1="{left + pw + 12}" x2="{left + pw + 32}" y1="{ly}" y2="{ly}" stroke="{colour}" '
                     f'stroke-width="3"/><text x="{left + pw + 38}" y="{ly + 4}" font-size="12">'
                     f"{escape(s.label)}</text>")
    parts.append("</svg>")
    return "".join(parts)


def bar_chart_svg(items: list[tuple[str, float]], *, unit: str = "s", width: int = 640) -> str:
    """Horizontal bars (e.g. stage timings), longest first in the given order."""
    if not items:
        return '<p class="missing">No timings to plot.</p>'
    top_value = max(v for _, v in items) or 1.0
    row, label_w = 20, 170
    height = row * len(items) + 10
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" width="{width}" '
             f'height="{height}" role="img" aria-label="timings" class="plot">']
    for i, (name, value) in enumerate(items):
        y = 5 + i * row
        w = (width - label_w - 80) * value / top_value
        parts.append(f'<text x="{label_w - 6}" y="{y + 13}" text-anchor="end" font-size="12">{escape(name)}</text>'
                     f'<rect x="{label_w}" y="{y + 2}" width="{w:.1f}" height="{row - 6}" fill="{PALETTE[0]}"/>'
                     f'<text x="{label_w + w + 4:.1f}" y="{y + 13}" font-size="11">{value:.1f} {unit}</text>')
    parts.append("</svg>")
    return "".join(parts)
