"""Run a selection of cases and turn the rows into the table and the JSON summary the report includes."""

from __future__ import annotations

import platform
import tempfile
import time
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import torch

from . import bad_input_cases, guard_cases, interrupted_cases, numerics_cases  # noqa: F401  (register the cases)
from .case_context import CaseContext
from .case_registry import CASES, GROUPS, Case, CaseResult, run_case

SUMMARY_FORMAT = 1


def select(names: Iterable[str] | None = None, groups: Iterable[str] | None = None) -> list[Case]:
    """Cases by name and/or group, in registration order; unknown names are a ValueError listing the known ones."""
    names = list(names or [])
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        raise ValueError(f"unknown stability cases {unknown}; known: {sorted(CASES)}")
    chosen = [c for c in CASES.values() if (not names or c.name in names)]
    groups = list(groups or [])
    chosen = [c for c in chosen if not groups or c.group in groups]
    return sorted(chosen, key=lambda c: GROUPS.index(c.group))  # numerics first, as the table reads


def run_suite(cases: list[Case], *, quick: bool = False, workdir: Path | None = None, device: str = "cpu",
              threads: int = 1, on_result: Any = None) -> dict[str, Any]:
    """Run ``cases`` (each in its own scratch folder) and return the JSON summary."""
    t0 = time.perf_counter()
    rows: list[CaseResult] = []
    torch_threads = torch.get_num_threads()
    try:
        with tempfile.TemporaryDirectory(prefix="livescene-stability-") as tmp:
            ctx = CaseContext(Path(workdir) if workdir else Path(tmp), quick=quick, device=device, threads=threads)
            for c in cases:
                row = run_case(c, ctx)
                rows.append(row)
                if on_result is not None:
                    on_result(row)
    finally:
        torch.set_num_threads(torch_threads)  # the cases pin torch to `threads`; the caller gets its own back
    counts = Counter(r.result for r in rows)
    return {
        "format": SUMMARY_FORMAT,
        "quick": quick,
        "counts": {k: counts.get(k, 0) for k in ("pass", "fail", "error", "skip")},
        "seconds": round(time.perf_counter() - t0, 1),
        "machine": {"python": platform.python_version(), "torch": torch.__version__,
                    "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
                    "threads": threads},
        "cases": [r.to_dict() for r in rows],
    }


def format_table(rows: list[dict[str, Any]], width: int = 100) -> str:
    """``case | result | metric`` as a plain-text table (the metric is cut to ``width`` characters)."""
    name_w = max([len("case"), *(len(r["name"]) for r in rows)])
    lines = [f"{'case'.ljust(name_w)} | result | metric", f"{'-' * name_w}-|--------|-{'-' * 40}"]
    for r in rows:
        text = r["metric"] if r["result"] == "pass" else r["detail"].splitlines()[-1] if r["detail"] else "-"
        if len(text) > width:
            text = text[: width - 3] + "..."
        lines.append(f"{r['name'].ljust(name_w)} | {r['result'].ljust(6)} | {text}")
    return "\n".join(lines)


def format_markdown(rows: list[dict[str, Any]]) -> str:
    """The same table in Markdown (docs/stability.md, the report): case | group | result | metric or reason."""
    lines = ["| case | group | result | metric (pass) or reason |", "|---|---|---|---|"]
    for r in rows:
        text = r["metric"] if r["result"] == "pass" else (r["detail"].splitlines()[-1] if r["detail"] else "-")
        lines.append(f"| {r['name']} | {r['group']} | {r['result']} | {text.replace('|', '/')} |")
    return "\n".join(lines)
