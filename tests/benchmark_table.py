"""Runs a stage benchmark script (benchmarks/*_throughput.py) in a smoke run and reads the table it prints."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "config" / "captures" / "tiny.yaml"
NUMERIC = ("median s", "n", "ms per unit", "units/s")
"""The columns every stage benchmark fills with a positive number on every row."""


def run_benchmark(script: str, work: Path, *args: str) -> tuple[str, list[dict[str, str]]]:
    """(everything printed, the table's rows as {column: cell}) of ``benchmarks/<script>`` on the tiny capture."""
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / script), "--capture", str(TINY), "--work",
                          str(work), "--repeats", "1", *args], check=True, capture_output=True, text=True,
                         cwd=ROOT).stdout
    lines = [line for line in out.splitlines() if line.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    rows = [dict(zip(header, (c.strip() for c in line.strip("|").split("|")), strict=True)) for line in lines[2:]]
    return out, rows


def check_table(out: str, rows: list[dict[str, str]], parts: list[str], extra: tuple[str, ...] = ()) -> None:
    """The header names the machine, its load and the peak RSS; every part has a row of positive finite numbers."""
    assert "machine: " in out and "before: load " in out and "peak RSS " in out
    assert float(out.split("peak RSS ")[1].split()[0]) > 0
    assert [r["part"] for r in rows] == parts
    for r in rows:
        assert list(r) == ["part", "median s", "n", "unit", "ms per unit", "units/s", *extra, "load"]
        for column in NUMERIC:
            value = float(r[column])
            assert math.isfinite(value) and value > 0, (r["part"], column, r[column])
        before, after = (float(v) for v in r["load"].split("-"))
        assert before >= 0 and after >= 0
