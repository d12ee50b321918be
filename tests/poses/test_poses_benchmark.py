"""benchmarks/poses_throughput.py in a smoke run on the tiny capture: COLMAP's steps as the stage times them."""

from __future__ import annotations

import pytest
from benchmark_table import check_table, run_benchmark


def test_poses_benchmark_prints_every_step(tiny_bench_work):
    out, rows = run_benchmark("poses_throughput.py", tiny_bench_work)
    check_table(out, rows, ["precheck", "masks", "extract", "match", "map", "export",
                            "other (untimed: frame list, motion check, gates)", "total"])
    seconds = {r["part"]: float(r["median s"]) for r in rows}
    # the steps and the untimed rest add up to the total (medians of one repeat; cells rounded to 4 digits)
    assert sum(v for k, v in seconds.items() if k != "total") == pytest.approx(seconds["total"], rel=0.01)
    assert "(30 images, 30 registered" in out
