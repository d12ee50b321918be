"""benchmarks/states_throughput.py in a smoke run on the tiny capture: the stage and every method timed."""

from __future__ import annotations

from benchmark_table import check_table, run_benchmark

from stages.states import METHODS


def test_states_benchmark_prints_every_method(tiny_bench_work):
    out, rows = run_benchmark("states_throughput.py", tiny_bench_work)
    check_table(out, rows, ["compute_states", *(f"interpolate {m}" for m in METHODS),
                            "leave_one_out (every method)"])
    assert rows[0]["n"] == "30" and rows[0]["unit"] == "frame"
    assert rows[1]["n"] == "60"  # 30 frames x 2 objects
