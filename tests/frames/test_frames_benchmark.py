"""benchmarks/frames_throughput.py in a smoke run on the tiny capture: every part timed, frames/s positive."""

from __future__ import annotations

from benchmark_table import check_table, run_benchmark


def test_frames_benchmark_prints_every_part(tiny_bench_work):
    out, rows = run_benchmark("frames_throughput.py", tiny_bench_work)
    check_table(out, rows, ["decode (open_source)", "sharpness (laplacian_variance)", "extract_frames",
                            "extract_frames --downscale 2 4"])
    assert {r["n"] for r in rows} == {"30"}  # the tiny video's frames, every one
    assert "kept 30 at 96x72" in out
