"""The whole workflow on the tiny synthetic capture (seconds of training), run twice in one DAG: as a
synthetic scene with truth, and as a user's own capture (its video, masks, key frames, names and prompts as
files, no truth). Every stage runs, both report pages hold real numbers and load in Chromium, a second run
has nothing to do, one scene can be built on its own, and `snakemake --report` works."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from stages.report.verdict_table import COLUMNS

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts" / "workflow"
USER_COMMANDS = ["close everything", "open the cupboard"]  # a synonym from prompts.yaml


@pytest.mark.slow
def test_tiny_scene_end_to_end(workflow_copy, tmp_path, chromium):
    wf = workflow_copy
    # what a user brings: a video and separate files, no truth, in a folder whose name holds a space and a "#"
    own = tmp_path / "own capture #1"
    subprocess.run([sys.executable, "-m", "stages.cli", "capture", "--spec", str(wf.root / "config/captures/tiny.yaml"),
                    "--out", str(own), "--no-progress"], check=True, capture_output=True)
    wf.write_scenes([{"scene": "tiny", "source": "synthetic", "path": "config/captures/tiny.yaml",
                      "poses": "estimate", "truth": "yes", "methods": "livescene"},
                     {"scene": "filmed", "source": "video", "path": own / "video.mp4", "poses": "estimate",
                      "masks": own / "masks", "key_frames": own / "key_frame_value.yaml",
                      "names": own / "mapping.yaml", "prompts": own / "prompts.yaml", "truth": "no",
                      "methods": "livescene"}])
    config = wf.write_config(train={"steps": 40, "max_seconds": 0, "eval_every": 20},
                             evaluate={"max_views": 1, "unseen_views": 1},
                             report={"sweep_steps": 2, "sweep_scale": 0.5, "grid_views": 1},
                             commands=USER_COMMANDS, stability={"run": False})
    run = wf.snakemake("--cores", "2", "--configfile", str(config), timeout=900)  # the default target
    assert run.code == 0, run.output[-4000:]

    results = wf.root / "results" / "tiny"
    for rule in ("capture", "frames", "poses", "pose_compare", "labels", "states", "assemble", "exposure",
                 "language_targets", "train_livescene", "evaluate_livescene", "sweep_livescene", "control_livescene",
                 "export_livescene", "report"):
        assert (results / "benchmarks" / f"{rule}.tsv").is_file(), rule
        assert (results / "logs" / f"{rule}.log").is_file(), rule
    # the frames' exposure measured once for the scene (train.appearance: auto), and the training read it
    appearance = json.loads((results / "runs" / "livescene" / "run.json").read_text())["appearance"]
    assert appearance["measured_by"] == "exposure file" and appearance["requested"] == "auto"
    assert appearance["spread"] == json.loads((results / "exposure.json").read_text())["spread"]
    exported = json.loads((results / "export" / "livescene" / "export.json").read_text())
    closed, opened = {"cabinet": 0.0, "drawer": 0.0}, {"cabinet": 1.0, "drawer": 1.0}  # config export.states
    assert [e["states"] for e in exported["exports"]] == [closed, opened]
    metrics = json.loads((results / "eval" / "livescene" / "metrics.json").read_text())
    assert math.isfinite(metrics["held_out"]["psnr"]["mean"])
    sweep = json.loads((results / "sweep" / "livescene" / "sweep.json").read_text())
    assert set(sweep["objects"]) == {"cabinet", "drawer"}
    assert all(len(v["images"]) == 2 for v in sweep["objects"].values())
    commands = json.loads((results / "control" / "livescene" / "commands.json").read_text())["commands"]
    assert [c["command"] for c in commands] == USER_COMMANDS and "error" not in commands[0]
    assert commands[0]["states"] == {"cabinet": 0.0, "drawer": 0.0}

    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["methods"]["livescene"]["psnr"] == pytest.approx(metrics["held_out"]["psnr"]["mean"])
    html = (wf.root / "reports" / "scenes" / "tiny.html").read_text()
    assert "planned (no benchmark yet)" not in html  # every needed rule ran and was measured
    assert "stability.run is false" in html and 'type="range"' in html
    assert "Export: meshes and point clouds" in html and "cabinet=1, drawer=1" in html
    assert html.count("data:image/png;base64,") >= 3 + 4 + 1  # grid (truth, render, error), sweeps, command
    _check_user_capture(wf)
    index = (wf.root / "reports" / "index.html").read_text()
    assert 'href="scenes/tiny.html"' in index and 'href="scenes/filmed.html"' in index
    # LiveScene alone in both scenes: no paired verdict, said so, and verdicts.csv holds its header only
    assert "No scene has a paired verdict" in index
    assert (wf.root / "reports" / "verdicts.csv").read_text().splitlines() == [",".join(COLUMNS)]
    for page in ("scenes/tiny.html", "index.html", "scenes/filmed.html"):  # the last one is kept as a picture
        chromium.load((wf.root / "reports" / page).as_uri())
        images = chromium.evaluate("Array.from(document.images).map(i => [i.alt, i.complete && i.naturalWidth > 0])")
        assert [alt for alt, ok in images if not ok] == [], page
        assert chromium.errors() == [], page
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    chromium.screenshot(ARTIFACTS / "no_truth_scene_page.png")  # the user-capture page, for a human to look at

    again = wf.snakemake("all", "-n", "--cores", "2", "--configfile", str(config))
    assert again.code == 0 and "Nothing to be done" in again.output

    # One scene on its own: only its jobs (and the index, which still lists the other scene's page).
    (wf.root / "reports" / "scenes" / "filmed.html").touch()
    alone = wf.snakemake("-n", "-p", "--cores", "2", "--configfile", str(config), "--config", "only=tiny",
                         "--forcerun", "report_scene")
    assert alone.code == 0, alone.output[-3000:]
    assert "scene=filmed" not in alone.output and "scene=tiny" in alone.output
    assert "--earlier results/filmed/report/summary.json" in alone.output  # listed apart from the earlier run

    # a training killed on its own (a scheduler's SIGTERM) leaves its checkpoint and no run.json: the rerun
    # trains again (resuming), then evaluates and reports again; it had said "Nothing to be done"
    killed = results / "runs" / "livescene" / "run.json"
    kept = shutil.copy2(killed, tmp_path / "run.json")
    killed.unlink()
    rerun = wf.snakemake("-n", "--cores", "2", "--configfile", str(config))
    assert rerun.code == 0 and "Nothing to be done" not in rerun.output, rerun.output[-3000:]
    jobs = rerun.jobs()
    assert jobs.get("train") == 1 and jobs.get("evaluate") == 1 and jobs.get("report_scene") == 1, jobs
    shutil.copy2(kept, killed)  # as it was (time stamp too): the rest of the test reads the finished run

    report = wf.snakemake("all", "--cores", "1", "--report", "report.zip", "--configfile", str(config))
    assert report.code == 0, report.output[-3000:]
    names = zipfile.ZipFile(wf.root / "report.zip").namelist()
    assert any(n.endswith("tiny.html") for n in names) and any(n.endswith("pose_error.json") for n in names)
    assert any(n.endswith("verdicts.csv") for n in names)


def _check_user_capture(wf):
    """The video scene without truth: no truth-based rule ran, its synonyms reached grounding and commands."""
    results = wf.root / "results" / "filmed"
    for rule in ("frames", "poses", "labels", "states", "assemble", "language_targets", "train_livescene",
                 "evaluate_livescene", "sweep_livescene", "control_livescene", "export_livescene", "report"):
        assert (results / "benchmarks" / f"{rule}.tsv").is_file(), rule
    assert not (results / "pose_error.json").exists() and not (results / "capture").exists()
    metrics = json.loads((results / "eval" / "livescene" / "metrics.json").read_text())
    assert math.isfinite(metrics["held_out"]["psnr"]["mean"])
    assert "unseen" not in metrics or not metrics["unseen"]
    synonyms = [q["query"] for q in metrics["grounding"]["queries"] if q["kind"] == "synonym"]
    assert sorted(synonyms) == ["cupboard", "top drawer"]  # from the user's prompts.yaml
    assert metrics["grounding"]["miou_probs_synonym"] is not None
    commands = json.loads((results / "control" / "livescene" / "commands.json").read_text())["commands"]
    assert commands[1]["command"] == "open the cupboard" and commands[1]["states"]["cabinet"] == 1.0
    html = (wf.root / "reports" / "scenes" / "filmed.html").read_text()
    assert "no truth" in html and "planned (no benchmark yet)" not in html
