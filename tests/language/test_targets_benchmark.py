"""benchmarks/language_targets_throughput.py in a smoke run on the tiny capture, with the offline MiniLM."""

from __future__ import annotations

from benchmark_table import check_table, run_benchmark


def test_targets_benchmark_prints_phrases_per_second(tiny_bench_work):
    out, rows = run_benchmark("language_targets_throughput.py", tiny_bench_work, "--levels-many", "11")
    check_table(out, rows, ["import sentence_transformers (first)", "load encoder (first, after the import)",
                            "load encoder (again)", "build_targets + write, levels 0,1, no cache",
                            "build_targets + write, 11 levels, no cache",
                            "build_targets + write, levels 0,1, disk cache"])
    # 2 objects: 2 x 2 phrases and the background; 2 x 11 and the background
    assert [r["n"] for r in rows[3:]] == ["5", "23", "5"]
    assert "all-MiniLM-L6-v2" in out
