"""benchmarks/evaluate_throughput.py in a smoke run: a tiny LiveScene run (4 steps) on the tiny capture, evaluated
against its truth renderer; every part the evaluation times has a row, renders have rays/s."""

from __future__ import annotations

from benchmark_table import check_table, run_benchmark

from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES


def test_evaluate_benchmark_prints_every_part(tiny_bench_work):
    train = [a for o in (*TINY_MODEL_OVERRIDES, "train.batch_rays=64", "train.threads=1") for a in ("--set", o)]
    out, rows = run_benchmark("evaluate_throughput.py", tiny_bench_work, "--steps", "4", *train, "--no-language",
                              "--no-grounding", "--views", "2", "--unseen-views", "1", "--locality-views", "1",
                              "--scale", "0.5")
    parts = ["held-out renders", "held-out scores", "unseen: model renders", "unseen: truth renders + scores",
             "locality (model + truth renders)", "evaluation (the four parts)", "livescene evaluate (in-process)",
             "livescene evaluate (first call)", "metric psnr", "metric ssim"]
    if "note: lpips:" not in out:  # LPIPS only where its weights are on this machine
        parts.append("metric lpips")
    check_table(out, rows, parts, extra=("rays/s",))
    by_part = {r["part"]: r for r in rows}
    assert by_part["held-out renders"]["n"] == "2" and "2 held-out views at 48x36" in out
    for part in ("held-out renders", "unseen: model renders"):
        assert float(by_part[part]["rays/s"]) > 0
    assert "note: grounding: skipped" in out
