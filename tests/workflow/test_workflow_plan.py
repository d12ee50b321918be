"""`snakemake -n`: each scene gets only the rules it needs; bad config and scene sheets are refused
with errors that name the file, the key and the row."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from workflow_copy import WorkflowCopy

from stages.scene import write_yaml

PIPELINE = {"capture", "frames", "poses", "pose_compare", "labels", "states", "assemble"}


def test_default_demo_runs_every_stage(workflow_copy):
    jobs = workflow_copy.dry_run().jobs()
    for rule in PIPELINE | {"language_targets", "sweep", "control", "stability", "report_scene", "report_index"}:
        assert jobs.get(rule) == 1, (rule, jobs)
    assert jobs["train"] == 3 and jobs["evaluate"] == 3  # livescene, mk-planes, conerf
    assert "capture_dataset" not in jobs and "scene_validate" not in jobs


@pytest.fixture(scope="module")
def mixed_plan(tmp_path_factory):
    """One dry run of four scenes: ready datasets with and without names, a filmed video without names,
    and a synthetic capture whose poses are given."""
    root = tmp_path_factory.mktemp("mixed")
    named, unnamed = root / "named", root / "unnamed"  # a dry run only needs the folders to exist
    named.mkdir()
    unnamed.mkdir()
    video = root / "room.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 5, (32, 24))
    for i in range(4):
        writer.write(np.full((24, 32, 3), 30 * i, np.uint8))
    writer.release()
    (root / "masks").mkdir()
    write_yaml(root / "keys.yaml", {"frame_00000": {"object0": 0.0}})
    wf = WorkflowCopy(root / "wf")
    wf.write_scenes([
        {"scene": "ready", "source": "dataset", "path": named, "poses": "given", "masks": "yes", "key_frames": "yes",
         "names": "yes", "truth": "no", "methods": "livescene,k-planes"},
        {"scene": "plain", "source": "dataset", "path": unnamed, "poses": "given", "names": "no",
         "methods": "livescene"},
        {"scene": "filmed", "source": "video", "path": video, "poses": "estimate", "masks": root / "masks",
         "key_frames": root / "keys.yaml", "names": "no", "truth": "no", "methods": "livescene"},
        {"scene": "given", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "truth": "yes", "methods": "livescene"}])
    return wf.dry_run()


def test_ready_dataset_with_poses_skips_frames_and_poses(mixed_plan):
    jobs = mixed_plan.scene_jobs("ready")
    assert not PIPELINE & set(jobs), sorted(jobs)
    assert len(jobs["scene_validate"]) == 1 and len(jobs["language_targets"]) == 1
    assert len(jobs["train"]) == 2 and len(jobs["evaluate"]) == 2
    assert not any("--truth" in text for text in jobs["evaluate"])  # no truth: no truth-based evaluation
    assert any("--method k-planes" in t for t in jobs["train"])
    assert not any("--method mk-planes" in t for t in jobs["train"])


def test_scene_without_names_skips_language(mixed_plan):
    for scene in ("plain", "filmed"):
        jobs = mixed_plan.scene_jobs(scene)
        assert "language_targets" not in jobs and "control" not in jobs, (scene, sorted(jobs))
        assert all("--no-grounding" in t for t in jobs["evaluate"])
        assert not any("--language-targets" in t for t in jobs["train"])
    filmed = mixed_plan.scene_jobs("filmed")
    assert {"frames", "poses", "labels", "states", "assemble"} <= set(filmed)
    assert "capture" not in filmed and "pose_compare" not in filmed
    assert "frames" not in mixed_plan.scene_jobs("plain")


def test_synthetic_with_given_poses_uses_the_truth_dataset(mixed_plan):
    jobs = mixed_plan.scene_jobs("given")
    assert {"capture", "capture_dataset", "language_targets", "train", "evaluate"} <= set(jobs)
    assert not {"frames", "poses", "pose_compare", "labels", "states", "assemble"} & set(jobs)
    assert all("--truth" in t and "--pose-alignment" not in t for t in jobs["evaluate"])


def test_config_error_names_file_key_and_type(workflow_copy):
    bad = workflow_copy.write_config(seed="zero", methods=["livescene", "nerf"])
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(bad))
    assert run.code != 0
    assert "test-config.yaml" in run.output
    assert "key 'seed'" in run.output and "'integer'" in run.output
    assert "key 'methods.1'" in run.output and "'nerf'" in run.output
    assert not (workflow_copy.root / "results").exists()


def test_scene_sheet_errors_name_line_scene_and_column(workflow_copy):
    workflow_copy.write_scenes([
        {"scene": "ok", "source": "synthetic", "path": "config/captures/tiny.yaml", "colour": "red"},
        {"scene": "typo", "source": "synthetik", "path": "x.yaml"},
        {"scene": "ready", "source": "dataset", "path": "somewhere", "poses": "estimate"},
        {"scene": "odd", "source": "synthetic", "path": "x.yaml", "methods": "livescene,nerf"},
        {"scene": "ok", "source": "synthetic", "path": "config/captures/tiny.yaml"}])
    sheet = workflow_copy.root / "config" / "scenes.tsv"
    lines = sheet.read_text().splitlines()
    sheet.write_text("\n".join([lines[0] + "\tcolour", lines[1] + "\tred", *lines[2:]]) + "\n")
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "config/scenes.tsv" in run.output
    assert "unknown column(s) ['colour']" in run.output
    assert "line 3 (scene 'typo'): key 'source'" in run.output and "'synthetik'" in run.output
    assert "line 4 (scene 'ready'): key 'poses'" in run.output
    assert "line 5 (scene 'odd'): key 'methods'" in run.output
    assert "duplicate scene name(s) ['ok']" in run.output
