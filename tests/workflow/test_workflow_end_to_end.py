"""The whole workflow on the tiny synthetic capture (seconds of training): every stage runs, the
report pages hold real numbers, a second run has nothing to do, and `snakemake --report` works."""

from __future__ import annotations

import json
import math
import zipfile

import pytest


@pytest.mark.slow
def test_tiny_scene_end_to_end(workflow_copy):
    wf = workflow_copy
    wf.write_scenes([{"scene": "tiny", "source": "synthetic", "path": "config/captures/tiny.yaml",
                      "poses": "estimate", "truth": "yes", "methods": "livescene"}])
    config = wf.write_config(train={"steps": 40, "max_seconds": 0, "eval_every": 20},
                             evaluate={"max_views": 1, "unseen_views": 1},
                             report={"sweep_steps": 2, "sweep_scale": 0.5, "grid_views": 1},
                             commands=["close everything"], stability={"run": False})
    run = wf.snakemake("--cores", "2", "--configfile", str(config), timeout=900)  # the default target
    assert run.code == 0, run.output[-4000:]

    results = wf.root / "results" / "tiny"
    for rule in ("capture", "frames", "poses", "pose_compare", "labels", "states", "assemble", "language_targets",
                 "train_livescene", "evaluate_livescene", "sweep_livescene", "control_livescene", "report"):
        assert (results / "benchmarks" / f"{rule}.tsv").is_file(), rule
        assert (results / "logs" / f"{rule}.log").is_file(), rule
    metrics = json.loads((results / "eval" / "livescene" / "metrics.json").read_text())
    assert math.isfinite(metrics["held_out"]["psnr"]["mean"])
    sweep = json.loads((results / "sweep" / "livescene" / "sweep.json").read_text())
    assert set(sweep["objects"]) == {"cabinet", "drawer"}
    assert all(len(v["images"]) == 2 for v in sweep["objects"].values())
    commands = json.loads((results / "control" / "livescene" / "commands.json").read_text())["commands"]
    assert [c["command"] for c in commands] == ["close everything"] and "error" not in commands[0]
    assert commands[0]["states"] == {"cabinet": 0.0, "drawer": 0.0}

    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["methods"]["livescene"]["psnr"] == pytest.approx(metrics["held_out"]["psnr"]["mean"])
    html = (wf.root / "reports" / "scenes" / "tiny.html").read_text()
    assert "planned (no benchmark yet)" not in html  # every needed rule ran and was measured
    assert "stability.run is false" in html and 'type="range"' in html
    assert html.count("data:image/png;base64,") >= 3 + 4 + 1  # grid (truth, render, error), sweeps, command
    index = (wf.root / "reports" / "index.html").read_text()
    assert 'href="scenes/tiny.html"' in index

    again = wf.snakemake("all", "-n", "--cores", "2", "--configfile", str(config))
    assert again.code == 0 and "Nothing to be done" in again.output

    report = wf.snakemake("all", "--cores", "1", "--report", "report.zip", "--configfile", str(config))
    assert report.code == 0, report.output[-3000:]
    names = zipfile.ZipFile(wf.root / "report.zip").namelist()
    assert any(n.endswith("tiny.html") for n in names) and any(n.endswith("pose_error.json") for n in names)
