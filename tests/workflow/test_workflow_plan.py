"""`snakemake -n`: each scene gets only the rules it needs; bad config and scene sheets are refused
with errors that name the file, the key and the row."""

from __future__ import annotations

import json
import re
import shlex

import cv2
import numpy as np
import pytest
import yaml
from workflow_copy import WorkflowCopy

from stages.scene import write_yaml

PIPELINE = {"capture", "frames", "poses", "pose_compare", "labels", "states", "assemble"}


def plan_of(run, scene: str) -> dict[str, bool]:
    """Rule -> needed, from the plan the scene's report page is given (report_scene's --plan-json)."""
    (text,) = run.scene_jobs(scene)["report_scene"]
    words = shlex.split(text.split("Shell command:", 1)[1].splitlines()[0])
    return {rule: entry["needed"] for rule, entry in json.loads(words[words.index("--plan-json") + 1]).items()}


def manifest_of(run, scene: str) -> dict:
    """The report page's inputs by role (report_scene's manifest, written to inputs.json)."""
    (text,) = run.scene_jobs(scene)["report_scene"]
    return json.loads(shlex.split(text.split("Shell command:", 1)[1].splitlines()[0])[2])


@pytest.fixture(scope="module")
def demo_plan(tmp_path_factory):
    """`snakemake -n` of the default sheet and config: the demo capture with truth, every item its own."""
    return WorkflowCopy(tmp_path_factory.mktemp("demo") / "wf").dry_run()


def test_default_demo_runs_every_stage(demo_plan):
    jobs = demo_plan.jobs()
    for rule in PIPELINE | {"language_targets", "sweep", "control", "stability", "report_scene", "report_index"}:
        assert jobs.get(rule) == 1, (rule, jobs)
    assert jobs["train"] == 3 and jobs["evaluate"] == 3  # livescene, mk-planes, conerf
    assert "capture_dataset" not in jobs and "scene_validate" not in jobs and "dataset_orient" not in jobs


def test_the_demo_plan_and_commands_follow_its_row_and_the_config(demo_plan):
    """The default row (a synthetic capture, poses estimated, every item the capture's own, truth) and config
    (methods livescene, mk-planes, conerf; sweeps and exports of livescene only; the stability suite)."""
    trained = ("livescene", "mk-planes", "conerf")
    needed = {"capture", "frames", "poses", "pose_compare", "labels", "states", "assemble", "exposure",
              "language_targets", "sweep[livescene]", "control[livescene]", "export[livescene]", "stability",
              *(f"{rule}[{m}]" for rule in ("train", "evaluate") for m in trained)}
    plan = plan_of(demo_plan, "demo")
    assert {rule for rule, wanted in plan.items() if wanted} == needed
    assert {"capture_dataset", "poses_import", "dataset_orient", "scene_validate", "train[k-planes]",
            "export[mk-planes]", "control[conerf]"} <= {rule for rule, wanted in plan.items() if not wanted}
    jobs = demo_plan.scene_jobs("demo")
    assert len(jobs["export"]) == 1 and "--method" not in jobs["export"][0]  # export.methods: [livescene]
    assert "--run results/demo/runs/livescene --" in jobs["export"][0] and "--objects" in jobs["export"][0]
    # the capture's own items: its masks keep COLMAP off the objects, its names, key frames and prompts
    assert "--masks results/demo/capture/masks " in jobs["poses"][0]
    assert "--input results/demo/capture/masks --mapping results/demo/capture/mapping.yaml " in jobs["labels"][0]
    assert ("--key-frames results/demo/capture/key_frame_value.yaml --mapping results/demo/capture/mapping.yaml "
            in jobs["states"][0])
    assert "--prompts results/demo/capture/prompts.yaml " in jobs["assemble"][0]
    # truth: the evaluation tests unseen combinations in the frame of the estimated poses
    assert len(jobs["evaluate"]) == 3 and all(
        "--truth results/demo/capture --pose-alignment results/demo/pose_error.json " in t for t in jobs["evaluate"])
    targets = [t for t in jobs["train"] if "--language-targets results/demo/language/targets.npz " in t]
    assert len(targets) == 1 and "--method livescene " in targets[0]  # only LiveScene has a language table
    manifest = manifest_of(demo_plan, "demo")
    assert manifest["stability"] == "results/stability/summary.json" and manifest["pose_error"].endswith(
        "results/demo/pose_error.json")
    assert set(manifest["export"]) == set(manifest["sweep"]) == set(manifest["control"]) == {"livescene"}
    assert set(manifest["runs"]) == set(manifest["eval"]) == set(trained)
    # every stage output the page digests (docs/workflow.md, "Where two runs part"), frames and exposure too
    assert manifest["frames"] == "results/demo/frames" and manifest["exposure"] == "results/demo/exposure.json"
    assert manifest["language"] == "results/demo/language/targets.npz"
    (index,) = [text for rule, text in demo_plan.blocks() if rule == "report_index"]
    assert " --csv reports/verdicts.csv --digests reports/digests.csv " in index.split("Shell command:", 1)[1]


def test_stability_and_exports_left_out_by_the_config(workflow_copy):
    """stability.run false and export.methods [] leave their jobs out of the plan, the targets and the page."""
    config = yaml.safe_load((workflow_copy.root / "config" / "config.yaml").read_text())
    chosen = workflow_copy.write_config(stability={**config["stability"], "run": False},
                                        export={**config["export"], "methods": []})
    run = workflow_copy.dry_run("--configfile", str(chosen))
    jobs = run.jobs()
    assert "stability" not in jobs and "export" not in jobs and jobs["sweep"] == 1, jobs
    plan = plan_of(run, "demo")
    assert not plan["stability"] and not plan["export[livescene]"] and plan["sweep[livescene]"]
    manifest = manifest_of(run, "demo")
    assert "stability" not in manifest and "export" not in manifest and "stability_benchmark" not in manifest
    assert "results/stability" not in run.output


@pytest.fixture(scope="module")
def mixed_plan(tmp_path_factory):
    """One dry run of four scenes: ready datasets with and without names, a filmed video without names,
    and a synthetic capture whose poses are given."""
    root = tmp_path_factory.mktemp("mixed")
    named, unnamed, learned = root / "named", root / "unnamed", root / "learned"  # a dry run needs them to exist
    for folder in (named, unnamed, learned):
        folder.mkdir()
    (learned / "mapping.yaml").write_text("1: door\n")
    (learned / "key_frame_value.yaml").write_text("frame_00000: {door: 0.0}\n")
    video = root / "room.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 5, (32, 24))
    for i in range(4):
        writer.write(np.full((24, 32, 3), 30 * i, np.uint8))
    writer.release()
    (root / "masks").mkdir()
    (root / "masks" / "mapping.yaml").write_text("1: object0\n")  # the id maps' names, without language ('no')
    write_yaml(root / "keys.yaml", {"frame_00000": {"object0": 0.0}})
    wf = WorkflowCopy(root / "wf")
    wf.write_scenes([
        {"scene": "ready", "source": "dataset", "path": named, "poses": "given", "masks": "yes", "key_frames": "yes",
         "names": "yes", "truth": "no", "methods": "livescene,k-planes"},
        {"scene": "plain", "source": "dataset", "path": unnamed, "poses": "given", "names": "no",
         "methods": "livescene"},
        {"scene": "learned", "source": "dataset", "path": learned, "poses": "given", "key_frames": "no",
         "names": "no", "methods": "livescene"},
        {"scene": "filmed", "source": "video", "path": video, "poses": "estimate", "masks": root / "masks",
         "key_frames": root / "keys.yaml", "names": "no", "truth": "no", "methods": "livescene"},
        {"scene": "given", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "truth": "yes", "methods": "livescene"},
        *({"scene": f"static{poses}", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": poses,
           "masks": "no", "key_frames": "no", "names": "no", "truth": "yes", "methods": "livescene"}
          for poses in ("given", "estimate")),
        {"scene": "baseline", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "truth": "yes", "methods": "mk-planes"},
        {"scene": "unmasked", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "masks": "no", "names": "no", "truth": "yes", "methods": "mk-planes"}])
    return wf.dry_run()


def test_ready_dataset_with_poses_skips_frames_and_poses(mixed_plan):
    jobs = mixed_plan.scene_jobs("ready")
    assert not PIPELINE & set(jobs), sorted(jobs)
    assert len(jobs["scene_validate"]) == 1 and len(jobs["language_targets"]) == 1
    # the ready dataset is copied into the upright world, and every model rule reads the copy
    assert len(jobs["dataset_orient"]) == 1 and "dataset orient --data" in jobs["dataset_orient"][0]
    assert all("results/ready/dataset" in t for t in jobs["train"])
    assert len(jobs["train"]) == 2 and len(jobs["evaluate"]) == 2
    assert not any("--truth" in text for text in jobs["evaluate"])  # no truth: no truth-based evaluation
    assert any("--method k-planes" in t for t in jobs["train"])
    assert not any("--method mk-planes" in t for t in jobs["train"])


def test_a_ready_dataset_without_key_frames_learns_its_states(mixed_plan):
    """`key_frames: no` on a ready dataset: its transforms.json's states are not read, LiveScene learns them between
    its key frames (docs/workflow.md, "The DAG")."""
    assert "--state-mode learned" in mixed_plan.scene_jobs("learned")["train"][0]
    assert not any("--state-mode" in t for t in mixed_plan.scene_jobs("ready")["train"])


def test_scene_without_names_skips_language(mixed_plan):
    for scene in ("plain", "filmed"):
        jobs = mixed_plan.scene_jobs(scene)
        assert "language_targets" not in jobs and "control" not in jobs, (scene, sorted(jobs))
        assert all("--no-grounding" in t for t in jobs["evaluate"])
        assert not any("--language-targets" in t for t in jobs["train"])
    filmed = mixed_plan.scene_jobs("filmed")
    assert {"frames", "poses", "labels", "states", "assemble"} <= set(filmed)
    # a long or large video is cut to config frames.count and .max_side, keeping the annotated frames
    frames = filmed["frames"][0]
    assert "--count 300 --max-side 960 --prefer-masked" in frames and "/masks" in frames
    assert not any("--missing-masks" in t for t in filmed["labels"])  # the default, the stage's own: propagate
    assert "capture" not in filmed and "pose_compare" not in filmed
    assert "frames" not in mixed_plan.scene_jobs("plain")


def test_language_targets_only_for_a_scene_that_trains_livescene(mixed_plan):
    jobs = mixed_plan.scene_jobs("baseline")  # names given, but only MK-Planes, which has no language table
    assert "language_targets" not in jobs and len(jobs["train"]) == 1
    assert len(mixed_plan.scene_jobs("given")["language_targets"]) == 1


def test_synthetic_with_given_poses_uses_the_truth_dataset(mixed_plan):
    jobs = mixed_plan.scene_jobs("given")
    assert {"capture", "capture_dataset", "language_targets", "train", "evaluate"} <= set(jobs)
    assert not {"frames", "poses", "pose_compare", "labels", "states", "assemble", "dataset_orient"} & set(jobs)
    assert all("--truth" in t and "--pose-alignment" not in t for t in jobs["evaluate"])


def test_a_synthetic_room_filmed_without_masks_and_key_frames_is_a_static_field(mixed_plan):
    """The capture's truth masks and states are not the row's: the dataset leaves them out, COLMAP gets no masks,
    and the evaluation has no objects to test against the truth (held-out views only)."""
    given = mixed_plan.scene_jobs("staticgiven")
    assert "--no-masks --no-states" in given["capture_dataset"][0]
    estimated = mixed_plan.scene_jobs("staticestimate")
    assert "--masks" not in estimated["poses"][0] and len(estimated["pose_compare"]) == 1
    for jobs in (given, estimated):
        assert not any("--truth" in t for t in jobs["evaluate"]) and "--state-mode learned" in jobs["train"][0]
    assert "--no-masks" not in mixed_plan.scene_jobs("given")["capture_dataset"][0]


def test_a_synthetic_room_filmed_without_masks_keeps_its_states_and_its_truth_test(mixed_plan):
    """Key frames without masks (a baseline that reads every state everywhere): the dataset leaves out the masks
    only, and the objects' states still let the evaluation test unseen combinations against the truth."""
    jobs = mixed_plan.scene_jobs("unmasked")
    assert "--no-masks" in jobs["capture_dataset"][0] and "--no-states" not in jobs["capture_dataset"][0]
    assert all("--truth results/unmasked/capture " in t for t in jobs["evaluate"])
    assert "--state-mode learned" not in jobs["train"][0]


def test_the_plan_of_each_kind_of_row(mixed_plan):
    """docs/workflow.md, "The DAG": which rules each kind of row leaves out."""
    trained = {"train[livescene]", "evaluate[livescene]", "sweep[livescene]", "export[livescene]", "exposure",
               "stability"}
    expected = {
        "ready": trained | {"scene_validate", "dataset_orient", "language_targets", "control[livescene]",
                            "train[k-planes]", "evaluate[k-planes]"},
        "filmed": trained | {"frames", "poses", "labels", "states", "assemble"},  # no names, no truth
        "given": trained | {"capture", "capture_dataset", "language_targets", "control[livescene]"},
        "staticestimate": trained | {"capture", "frames", "poses", "pose_compare", "assemble"},
        "baseline": {"capture", "capture_dataset", "train[mk-planes]", "evaluate[mk-planes]", "exposure",
                     "stability"},
    }
    expected["unmasked"] = expected["baseline"]
    for scene, rules in expected.items():
        plan = plan_of(mixed_plan, scene)
        assert {rule for rule, wanted in plan.items() if wanted} == rules, scene
    # each evaluation says what it tests (the page's plan table), from the truth and the objects the row has
    (report,) = mixed_plan.scene_jobs("staticgiven")["report_scene"]
    assert "held-out views only: no objects to test against the truth" in report
    (report,) = mixed_plan.scene_jobs("filmed")["report_scene"]
    assert "held-out views only: no truth" in report and "no objects" not in report


def test_config_error_names_file_key_and_type(workflow_copy):
    bad = workflow_copy.write_config(seed="zero", methods=["livescene", "nerf"])
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(bad))
    assert run.code != 0
    assert "test-config.yaml" in run.output
    assert "key 'seed'" in run.output and "'integer'" in run.output
    assert "key 'methods.1'" in run.output and "'nerf'" in run.output
    assert not (workflow_copy.root / "results").exists()


def test_a_preset_that_names_no_file_and_a_method_given_twice_are_refused(workflow_copy):
    """A preset typo had dropped the trainings it could not feed: "Nothing to be done" over the old report."""
    typo = workflow_copy.write_config(preset="gpu-papr")
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(typo))
    assert run.code != 0 and "key 'preset': preset 'gpu-papr' not found" in run.output
    twice = workflow_copy.write_config(methods=["livescene", "livescene"])
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(twice))
    assert run.code != 0 and "key 'methods'" in run.output


def test_frame_limits_a_capture_does_not_reach_are_not_named(workflow_copy):
    """The demo (80 frames of 256x192) is within frames.count and .max_side: its command names neither, so changing
    a limit it does not reach reruns nothing; a limit that bites is named."""
    frames = workflow_copy.dry_run().scene_jobs("demo")["frames"][0]
    assert "--count" not in frames and "--max-side" not in frames
    tight = workflow_copy.write_config(frames={"count": 40, "max_side": 128})
    frames = workflow_copy.dry_run("--configfile", str(tight)).scene_jobs("demo")["frames"][0]
    assert "--count 40 --max-side 128" in frames


def test_a_nested_number_given_on_the_command_line_is_read_as_a_number(workflow_copy):
    """Snakemake reads `--config train='{steps: 61}'` with YAML's base loader: '61' was refused as a string."""
    jobs = workflow_copy.dry_run("--config", "train={steps: 61}").scene_jobs("demo")
    assert all("--max-steps 61" in t for t in jobs["train"])
    run = workflow_copy.snakemake("-n", "--cores", "1", "--config", "train={steps: many}")
    assert run.code != 0 and "key 'train.steps': 'many' is not of type 'integer'" in run.output
    assert "--config" in run.output.split("invalid workflow config in")[1].splitlines()[0]


def test_missing_masks_policy_reaches_the_labels_stage_and_is_checked(workflow_copy):
    leave = workflow_copy.write_config(labels={"missing_masks": "leave"})
    jobs = workflow_copy.dry_run("--configfile", str(leave)).scene_jobs("demo")
    assert len(jobs["labels"]) == 1 and "--missing-masks leave" in jobs["labels"][0]
    bad = workflow_copy.write_config(labels={"missing_masks": "guess"})
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(bad))
    assert run.code != 0
    assert "key 'labels.missing_masks'" in run.output and "'guess'" in run.output


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
    assert "line 4 (scene 'ready'): column 'poses'" in run.output
    assert "line 5 (scene 'odd'): key 'methods'" in run.output
    assert "column 'scene': 'ok' names the rows of lines 2, 6; fix: give each row its own scene name" in run.output


def test_scene_sheet_checks_values_against_the_source(workflow_copy, tmp_path):
    video = tmp_path / "room.mp4"
    video.write_bytes(b"")  # a dry run only needs the file to exist
    (tmp_path / "shots").mkdir()
    learned, keyed, static = (tmp_path / name for name in ("learned", "keyed", "static"))
    for ds in (learned, keyed, static):
        ds.mkdir()
    for ds in (learned, keyed):
        (ds / "mapping.yaml").write_text("1: door\n")
    (keyed / "key_frame_value.yaml").write_text("frame_00000: {door: 0.0}\n")
    workflow_copy.write_scenes([
        {"scene": "none", "source": "video", "path": video, "masks": "no", "key_frames": "no", "names": "no",
         "truth": "none"},
        {"scene": "yes", "source": "video", "path": video, "masks": "yes", "key_frames": "no", "names": "no"},
        {"scene": "gone", "source": "video", "path": tmp_path / "gone.mp4", "masks": "no", "key_frames": "no",
         "names": tmp_path / "mapping.yaml", "truth": "yes"},
        {"scene": "model", "source": "video", "path": video, "poses": "colmap:" + str(tmp_path), "masks": "no",
         "key_frames": "no", "names": "no"},
        {"scene": "nomodel", "source": "images", "path": tmp_path / "shots", "poses": "colmap:/no/such/sparse",
         "masks": "no", "key_frames": "no", "names": "no"},
        {"scene": "keyless", "source": "images", "path": tmp_path / "shots", "masks": tmp_path / "shots",
         "key_frames": "no", "names": "no"},
        {"scene": "truthkeyless", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "key_frames": "no", "names": "no", "truth": "yes"},
        *({"scene": ds.name, "source": "dataset", "path": ds, "poses": "given", "key_frames": "no", "names": "no"}
          for ds in (learned, keyed, static))])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "line 2 (scene 'none'): column 'truth': 'none' is not 'yes', 'no' or a capture folder" in run.output
    assert "line 3 (scene 'yes'): column 'masks': 'yes' means the source itself holds it" in run.output
    assert "line 4 (scene 'gone'): column 'path'" in run.output and "gone.mp4' does not exist" in run.output
    assert "line 4 (scene 'gone'): column 'names'" in run.output
    assert "line 4 (scene 'gone'): column 'truth': 'yes' means a synthetic capture's own truth" in run.output
    assert "line 5 (scene 'model'): column 'poses': a COLMAP model is matched to an image folder" in run.output
    assert "line 6 (scene 'nomodel'): column 'poses': COLMAP model folder '/no/such/sparse' does not exist" \
        in run.output
    assert "line 7 (scene 'keyless'): column 'key_frames': the masks make objects, but without key frames" \
        in run.output
    assert "line 8 (scene 'truthkeyless'): column 'key_frames': the masks make objects" in run.output
    assert "line 2 (scene 'none'): column 'key_frames'" not in run.output  # no masks: a static room
    # a ready dataset: its objects (mapping.yaml) need its key frames for learned states; without objects, or
    # with key frames, 'no' is fine
    assert "line 9 (scene 'learned'): column 'key_frames': 'no' trains the dataset's objects" in run.output
    assert "(scene 'keyed'): column 'key_frames'" not in run.output
    assert "(scene 'static'): column 'key_frames'" not in run.output
    assert "MissingInputException" not in run.output


def test_rows_whose_items_cannot_go_together_are_refused_before_any_job(workflow_copy, tmp_path):
    """What a stage would refuse after frames and COLMAP ran is refused when the sheet is read, with the sheet fix."""
    video = tmp_path / "room.mp4"
    video.write_bytes(b"")
    maps, keys_dir = tmp_path / "maps", tmp_path / "keys"
    maps.mkdir()
    keys_dir.mkdir()
    (maps / "frame_00000.png").write_bytes(b"")
    keys = tmp_path / "keys.csv"
    keys.write_text("frame,object,value\n0,door,0\n")
    names = tmp_path / "names" / "mapping.yaml"  # not beside the masks, where the labels stage would find it
    names.parent.mkdir()
    names.write_text("1: door\n")
    workflow_copy.write_scenes([
        {"scene": "nomasks", "source": "video", "path": video, "masks": "no", "key_frames": keys, "names": "no"},
        {"scene": "unnamed", "source": "video", "path": video, "masks": maps, "key_frames": keys, "names": "no"},
        {"scene": "static", "source": "video", "path": video, "masks": "no", "key_frames": "no", "names": names},
        {"scene": "ranges", "source": "video", "path": video, "masks": maps, "key_frames": keys, "names": names,
         "state_ranges": "door=90,0;oven=0,1;lid=a,b"},
        {"scene": "keydir", "source": "video", "path": video, "masks": maps, "key_frames": keys_dir, "names": names},
        {"scene": "fine", "source": "video", "path": video, "masks": "no", "key_frames": keys, "names": "no",
         "methods": "mk-planes, k-planes"},  # spaces after the commas, as one writes a list
        {"scene": "ready", "source": "dataset", "path": maps, "poses": "given", "masks": "no", "prompts": keys},
    ])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    out = run.output
    assert "(scene 'nomasks'): column 'masks': 'no', but ['conerf', 'livescene'] learn which pixels" in out
    assert "(scene 'unnamed'): column 'names': 'no', but the id maps of" in out
    assert "(scene 'static'): column 'names': the row has neither masks nor key frames" in out
    assert "'door=90,0' has LO 90 not below HI 0" in out and "'oven' is no object of" in out
    assert "'lid=a,b' is not OBJECT=LO,HI" in out
    assert "(scene 'keydir'): column 'key_frames':" in out and "is a folder; fix: give the key-frame file" in out
    assert "(scene 'fine')" not in out
    assert "(scene 'ready'): column 'masks': 'no', but a ready dataset's masks are part of it" in out
    assert "(scene 'ready'): column 'prompts': a ready dataset's prompts are its prompts.yaml" in out
    sheet = workflow_copy.root / "config" / "scenes.tsv"
    sheet.write_text(sheet.read_text().replace("\t", ","))
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0 and "the header line has commas but no tab" in run.output


def test_scene_sheet_comments_ragged_rows_empty_cells_and_an_empty_sheet(workflow_copy, tmp_path):
    room = tmp_path / "room #2"  # a "#" inside a path is not a comment
    room.mkdir()
    (room / "video.mp4").write_bytes(b"")
    sheet = workflow_copy.root / "config" / "scenes.tsv"
    sheet.write_text("scene\tsource\tpath\n"
                     "# an old scene, commented out\n"
                     f"bare\tvideo\t{room / 'video.mp4'}\n"
                     "\n"
                     f"extra\tvideo\t{room / 'video.mp4'}\tno\n")
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "line 3 (scene 'bare'): column 'masks': is empty or absent, so it takes its default 'yes'" in run.output
    assert "does not exist" not in run.output  # the path with its "#" was read whole
    assert "line 5: 4 tab-separated cells but the header has 3 columns" in run.output
    assert "MissingInputException" not in run.output
    sheet.write_text("# nothing yet\n\n")
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0 and "the scene sheet is empty; fix: write a tab-separated header line" in run.output
    assert "EmptyDataError" not in run.output


def test_imported_colmap_model_replaces_sfm_and_prompts_reach_assembly(workflow_copy, tmp_path):
    shots, model, truth = tmp_path / "shots", tmp_path / "sparse" / "0", tmp_path / "capture"
    for folder in (shots, model, truth / "truth"):
        folder.mkdir(parents=True)
    (truth / "truth" / "transforms.json").write_text("{}")
    for name in ("mapping.yaml", "prompts.yaml", "keys.yaml"):
        (tmp_path / name).write_text("{}")
    (tmp_path / "masks").mkdir()
    workflow_copy.write_scenes([
        {"scene": "shots", "source": "images", "path": shots, "poses": f"colmap:{model}", "masks": tmp_path / "masks",
         "key_frames": tmp_path / "keys.yaml", "names": tmp_path / "mapping.yaml",
         "prompts": tmp_path / "prompts.yaml", "truth": truth, "methods": "livescene"}])
    jobs = workflow_copy.dry_run().scene_jobs("shots")
    assert "poses" not in jobs and len(jobs["poses_import"]) == 1
    assert f"--model {model} --frames results/shots/frames --out results/shots/poses" in jobs["poses_import"][0]
    assert {"frames", "states", "assemble", "pose_compare", "language_targets"} <= set(jobs)
    assert f"--prompts {tmp_path / 'prompts.yaml'}" in jobs["assemble"][0]
    assert " dataset assemble --frames results/shots/frames " in jobs["assemble"][0]  # the dataset stage's command
    assert all(f"--truth {truth}" in t for t in jobs["evaluate"])


def test_mask_file_reaches_colmap_through_the_labels_stage(workflow_copy, tmp_path):
    """A folder of id maps goes to COLMAP as it is (also as a masks/ subfolder); a COCO / LabelMe file, and one
    folder of masks per object, go through the labels stage's id maps."""
    video, folder, coco = tmp_path / "room.mp4", tmp_path / "masks", tmp_path / "masks.json"
    video.write_bytes(b"")  # a dry run only needs the paths to exist
    folder.mkdir()
    (folder / "frame_00000.png").write_bytes(b"")
    coco.write_text("{}")
    nested, per_object = tmp_path / "annotations", tmp_path / "per_object"
    (nested / "masks").mkdir(parents=True)
    (nested / "masks" / "frame_00000.png").write_bytes(b"")
    (per_object / "fridge").mkdir(parents=True)
    (per_object / "fridge" / "frame_00000.png").write_bytes(b"")
    names, keys = tmp_path / "mapping.yaml", tmp_path / "keys.yaml"
    names.write_text("{1: fridge}")
    keys.write_text("{frame_00000: {fridge: 0.0}}")
    row = {"source": "video", "path": video, "poses": "estimate", "key_frames": keys, "names": names,
           "truth": "no", "methods": "livescene"}
    workflow_copy.write_scenes([{"scene": "folder", "masks": folder, **row}, {"scene": "file", "masks": coco, **row},
                                {"scene": "nested", "masks": nested, **row},
                                {"scene": "objects", "masks": per_object, **row}])
    plan = workflow_copy.dry_run()
    assert f"--masks {folder} " in plan.scene_jobs("folder")["poses"][0]
    assert f"--masks {nested / 'masks'} " in plan.scene_jobs("nested")["poses"][0]
    for scene in ("file", "objects"):
        poses = plan.scene_jobs(scene)["poses"][0]
        inputs = re.search(r"^\s*input: (.*)$", poses, re.M)
        assert f"--masks results/{scene}/labels/masks " in poses and inputs
        assert f"results/{scene}/labels" in inputs.group(1)


def test_state_ranges_reach_the_states_stage_and_are_checked(workflow_copy, tmp_path):
    """Key frames in a unit of the user's get fixed ranges from the sheet (min-max would stretch an object that
    barely moves to its whole range); the column is refused where no states stage runs, and when malformed."""
    video, keys, names = tmp_path / "room.mp4", tmp_path / "keys.csv", tmp_path / "mapping.yaml"
    video.write_bytes(b"")  # a dry run only needs the paths to exist
    keys.write_text("frame,object,value\n0,wardrobe,0\n")
    names.write_text("{1: wardrobe, 2: left drawer}")
    (tmp_path / "masks").mkdir()
    row = {"source": "video", "path": video, "poses": "estimate", "masks": tmp_path / "masks", "key_frames": keys,
           "names": names,
           "truth": "no", "methods": "livescene"}
    workflow_copy.write_scenes([{"scene": "filmed", "state_ranges": "wardrobe=0,95;left drawer=0,25", **row},
                                {"scene": "plain", **row}])
    plan = workflow_copy.dry_run()
    assert "--range wardrobe=0,95 --range 'left drawer=0,25'" in plan.scene_jobs("filmed")["states"][0]
    assert "--range" not in plan.scene_jobs("plain")["states"][0]
    ready = tmp_path / "ready"
    ready.mkdir()
    workflow_copy.write_scenes([{"scene": "ready", "source": "dataset", "path": ready, "poses": "given",
                                 "state_ranges": "drawer=0,1"},
                                {"scene": "typo", "state_ranges": "wardrobe=0-95", **row}])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    # a ready dataset's key frames are normalised by the trainer: its fixed ranges go in its scene.json
    assert "line 2 (scene 'ready'): column 'state_ranges': a ready dataset's key frames are normalised by the " \
        "trainer" in run.output and "scene.json" in run.output
    assert "line 3 (scene 'typo'): key 'state_ranges'" in run.output


def test_only_builds_the_named_scenes(workflow_copy):
    workflow_copy.write_scenes([
        {"scene": "a", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"},
        {"scene": "b", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"}])
    run = workflow_copy.dry_run("--config", "only=b")
    assert run.scene_jobs("b") and not run.scene_jobs("a")
    index = [text for rule, text in run.blocks() if rule == "report_index"]
    assert len(index) == 1 and "--pending a" in index[0]
    bad = workflow_copy.snakemake("-n", "--cores", "1", "--config", "only=c")
    assert bad.code != 0 and "config key 'only': scene(s) ['c'] are not in the scene sheet" in bad.output
    # named as one writes a list, or twice: each scene once
    run = workflow_copy.dry_run("--config", "only= b, b")
    index = [text for rule, text in run.blocks() if rule == "report_index"]
    assert "input: results/b/report/summary.json, reports/scenes/b.html\n" in index[0]
    # the sheet's name mistaken for the selection points to 'only'
    bad = workflow_copy.snakemake("-n", "--cores", "1", "--config", "scenes=b")
    assert bad.code != 0 and "to build some scenes of the sheet, name them with --config only=b" in bad.output


def test_only_lists_pages_of_earlier_runs_apart_and_names_the_scenes_without_one(workflow_copy):
    """An earlier page counts when both its summary and its page are there; a scene with only one of them (a run
    stopped between the two, a page deleted) has no page to list."""
    tiny = {"source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"}
    workflow_copy.write_scenes([{"scene": s, **tiny} for s in ("built", "summary", "page", "new", "now")])
    for scene in ("built", "summary"):
        summary = workflow_copy.root / "results" / scene / "report" / "summary.json"
        summary.parent.mkdir(parents=True)
        summary.write_text("{}")
    for scene in ("built", "page"):
        page = workflow_copy.root / "reports" / "scenes" / f"{scene}.html"
        page.parent.mkdir(parents=True, exist_ok=True)
        page.write_text("<html></html>")
    run = workflow_copy.dry_run("--config", "only=now")
    (index,) = [text for rule, text in run.blocks() if rule == "report_index"]
    command = index.split("Shell command:", 1)[1]
    assert "--earlier results/built/report/summary.json --pending summary,page,new " in command


def test_a_wrong_row_not_selected_does_not_hold_up_the_others(workflow_copy, tmp_path):
    workflow_copy.write_scenes([
        {"scene": "a", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene"},
        {"scene": "b", "source": "synthetic", "path": "config/captures/tiny.yaml", "methods": "livescene",
         "masks": tmp_path / "missing_masks"},
        {"scene": "c", "source": "synthetic", "path": "config/captures/tiny.yaml",
         "methods": "livescene,mk-planes,livescene"}])
    run = workflow_copy.dry_run("--config", "only=a")
    assert run.scene_jobs("a") and not run.scene_jobs("b") and not run.scene_jobs("c")
    assert "warning: " in run.output and "line 3 is left out of this run (not named by 'only')" in run.output
    assert "missing_masks' does not exist" in run.output
    assert "line 4 is left out" in run.output and "livescene listed more than once" in run.output
    every = workflow_copy.snakemake("-n", "--cores", "1")  # every row asked for: every wrong cell refused
    assert every.code != 0 and "line 3 (scene 'b'): column 'masks'" in every.output
    assert "line 4 (scene 'c'): column 'methods': livescene listed more than once" in every.output
    named = workflow_copy.snakemake("-n", "--cores", "1", "--config", "only=a,b")
    assert named.code != 0 and "line 3 (scene 'b')" in named.output


def test_poses_orient_false_keeps_every_world(workflow_copy, tmp_path):
    ready = tmp_path / "ready"
    ready.mkdir()  # a dry run only needs the folder to exist
    workflow_copy.write_scenes([
        {"scene": "demo", "source": "synthetic", "path": "config/captures/demo.yaml"},
        {"scene": "ready", "source": "dataset", "path": ready, "poses": "given", "names": "no",
         "methods": "livescene"}])
    default = workflow_copy.dry_run()
    assert "--no-orient" not in default.scene_jobs("demo")["poses"][0]
    assert "dataset_orient" in default.scene_jobs("ready")
    keep = workflow_copy.write_config(poses={"orient": False})
    plan = workflow_copy.dry_run("--configfile", str(keep))
    assert "--no-orient" in plan.scene_jobs("demo")["poses"][0]
    jobs = plan.scene_jobs("ready")
    assert "dataset_orient" not in jobs and all(str(ready) in t for t in jobs["train"])


def test_appearance_correction_reaches_every_training(workflow_copy):
    """auto by default (measured gains divided out where they vary); every mode reaches every training (none: the
    reference's images). The exposure is measured once per scene (rule
    exposure) and every training reads that file; modes that measure nothing have no such rule."""
    plan = workflow_copy.dry_run().scene_jobs("demo")
    jobs = plan["train"]
    assert len(jobs) == 3 and all("--set model.appearance.mode=auto" in t for t in jobs)
    assert len(plan["exposure"]) == 1 and "scene exposure results/demo/dataset --out results/demo/exposure.json" in \
        plan["exposure"][0]
    assert all("--exposure results/demo/exposure.json" in t for t in jobs)
    for mode in ("none", "affine"):
        chosen = workflow_copy.write_config(train={"appearance": mode})
        plan = workflow_copy.dry_run("--configfile", str(chosen)).scene_jobs("demo")
        jobs = plan["train"]
        assert len(jobs) == 3 and "exposure" not in plan and not any("--exposure" in t for t in jobs)
        # named even for none: a preset file of the user's that sets a mode must not win over the workflow key
        assert all(f"--set model.appearance.mode={mode}" in t for t in jobs)
    for mode in ("measured", "auto"):
        chosen = workflow_copy.write_config(train={"appearance": mode})
        plan = workflow_copy.dry_run("--configfile", str(chosen)).scene_jobs("demo")
        jobs = plan["train"]
        assert len(jobs) == 3 and all(f"--set model.appearance.mode={mode}" in t for t in jobs)
        assert len(plan["exposure"]) == 1 and all("--exposure results/demo/exposure.json" in t for t in jobs)


def test_camera_refinement_reaches_every_training_only_when_asked(workflow_copy):
    """train.camera_opt "off" (the default) leaves the training command as it was; SO3xR3 reaches every method's;
    a bare YAML off (false) is refused by the schema, not read as a mode."""
    jobs = workflow_copy.dry_run().scene_jobs("demo")["train"]
    assert len(jobs) == 3 and not any("--camera-opt" in t for t in jobs)
    chosen = workflow_copy.write_config(train={"camera_opt": "SO3xR3"})
    jobs = workflow_copy.dry_run("--configfile", str(chosen)).scene_jobs("demo")["train"]
    assert len(jobs) == 3 and all("--camera-opt SO3xR3" in t for t in jobs)
    bare = workflow_copy.write_config(train={"camera_opt": False})
    failed = workflow_copy.snakemake("-n", "--cores", "2", "--configfile", str(bare))
    assert failed.code != 0 and "camera_opt" in failed.output


def test_sheet_cells_that_only_look_wrong_are_accepted(workflow_copy, tmp_path):
    """A spreadsheet's BOM, `*` in state_ranges, a mapping.yaml one folder above the id maps, one mask folder per
    object (named by its folders) with `names: no`, and a COLMAP model folder with a colon in its path."""
    video, keys, names = tmp_path / "room.mp4", tmp_path / "keys.csv", tmp_path / "mapping.yaml"
    video.write_bytes(b"")  # a dry run only needs the paths to exist
    keys.write_text("frame,object,value\n0,door,0\n")
    names.write_text("{1: door}")
    maps = tmp_path / "annotations" / "masks"
    maps.mkdir(parents=True)
    (maps / "frame_00000.png").write_bytes(b"")
    (maps.parent / "mapping.yaml").write_text("{1: door}")
    per_object = tmp_path / "cut" / "per_object" / "door"  # no mapping.yaml in it or above it
    per_object.mkdir(parents=True)
    (per_object / "frame_00000.png").write_bytes(b"")
    shots, model = tmp_path / "shots", tmp_path / "run:2" / "sparse"
    shots.mkdir()
    model.mkdir(parents=True)
    row = {"source": "video", "path": video, "key_frames": keys, "truth": "no", "methods": "livescene"}
    sheet = workflow_copy.write_scenes([
        {"scene": "star", "masks": maps, "names": names, "state_ranges": "*=0,90", **row},
        {"scene": "parent", "masks": maps, "names": "no", **row},
        {"scene": "objects", "masks": per_object.parent, "names": "no", **row},
        {"scene": "unmasked", "masks": "no", "names": names, **row, "methods": "mk-planes"},  # names, key frames
        {"scene": "model", "source": "images", "path": shots, "poses": f"colmap:{model}", "masks": "no",
         "key_frames": "no", "names": "no", "methods": "mk-planes"}])
    sheet.write_text("\ufeff" + sheet.read_text(), encoding="utf-8")  # "CSV UTF-8" of a spreadsheet
    plan = workflow_copy.dry_run()
    assert "--range '*=0,90'" in plan.scene_jobs("star")["states"][0]
    assert f"--input {maps} --mapping {names} --frames " in plan.scene_jobs("star")["labels"][0]
    assert f"--key-frames {keys} --mapping {names} --frames " in plan.scene_jobs("unmasked")["states"][0]
    assert {"labels", "states", "assemble"} <= set(plan.scene_jobs("parent")) and plan.scene_jobs("objects")
    assert f"--model {model} " in plan.scene_jobs("model")["poses_import"][0]


def test_sheet_cells_that_are_wrong_for_their_row_are_refused(workflow_copy, tmp_path):
    video, keys = tmp_path / "room.mp4", tmp_path / "keys.csv"
    video.write_bytes(b"")
    keys.write_text("frame,object,value\n0,door,0\n")
    (tmp_path / "shots").mkdir()
    (tmp_path / "masks").mkdir()
    filmed = {"source": "video", "path": video, "masks": tmp_path / "masks", "key_frames": keys, "names": "no"}
    workflow_copy.write_scenes([
        {"scene": "posedvideo", "poses": "given", **filmed},
        {"scene": "posedshots", **filmed, "source": "images", "path": tmp_path / "shots", "poses": "given"},
        {"scene": "flat", "state_ranges": "door=5,5", **filmed},
        {"scene": "keyless", **filmed, "masks": "no", "key_frames": "no", "methods": "mk-planes",
         "state_ranges": "door=0,1"},
        {"scene": "truthful", "source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given",
         "truth": "yes", "state_ranges": "drawer=0,1"}])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "line 2 (scene 'posedvideo'): column 'poses': a video source has no poses to give" in run.output
    assert "line 3 (scene 'posedshots'): column 'poses': a images source has no poses to give" in run.output
    assert "line 4 (scene 'flat'): column 'state_ranges': 'door=5,5' has LO 5 not below HI 5" in run.output
    for line, scene in ((5, "keyless"), (6, "truthful")):  # no states stage interpolates their key frames
        assert f"line {line} (scene '{scene}'): column 'state_ranges': only key frames that the states stage" \
            in run.output
    sheet = workflow_copy.root / "config" / "scenes.tsv"
    sheet.write_text(sheet.read_text().splitlines()[0] + "\n")  # the header alone
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0 and "- no scene rows" in run.output


def test_a_synthetic_row_with_given_poses_is_refused_what_a_filmed_one_is(workflow_copy):
    """Its dataset is written from the capture leaving out what the row leaves out (capture dataset --no-masks), so
    its items pair as a filmed row's: key frames without masks had passed the sheet and failed LiveScene's training
    after the capture ("no training frame has a mask")."""
    tiny = {"source": "synthetic", "path": "config/captures/tiny.yaml", "poses": "given", "truth": "yes"}
    workflow_copy.write_scenes([
        {"scene": "unmasked", "masks": "no", "names": "no", "methods": "livescene", **tiny},
        {"scene": "baseline", "masks": "no", "names": "no", "methods": "mk-planes", **tiny},
        {"scene": "static", "masks": "no", "key_frames": "no", "methods": "mk-planes", **tiny}])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "line 2 (scene 'unmasked'): column 'masks': 'no', but ['livescene'] learn which pixels" in run.output
    assert "line 4 (scene 'static'): column 'names': the row has neither masks nor key frames" in run.output
    assert "(scene 'baseline')" not in run.output


def test_a_quoted_number_of_a_config_file_stays_an_error(workflow_copy):
    """Only `--config` values are read again as numbers (Snakemake's loader makes them text); a config file's
    quoted number is the user's mistake, named."""
    quoted = workflow_copy.write_config(train={"steps": "61"})
    run = workflow_copy.snakemake("-n", "--cores", "1", "--configfile", str(quoted))
    assert run.code != 0 and "key 'train.steps': '61' is not of type 'integer'" in run.output
    assert "--config" not in run.output.split("invalid workflow config in")[1].splitlines()[0]  # none was given
    run = workflow_copy.snakemake("-n", "--cores", "1", "--config", "train={steps: true}")
    assert run.code != 0 and "key 'train.steps'" in run.output


def test_camera_column_gives_colmap_the_focal_length(workflow_copy, tmp_path):
    """A known focal length (sheet column `camera`) reaches the poses command; a row without one keeps the command
    it had (so it reruns nothing), and the column is refused where COLMAP does not run or when not positive."""
    video = tmp_path / "room.mp4"
    video.write_bytes(b"")  # a dry run only needs the paths to exist
    row = {"source": "video", "path": video, "poses": "estimate", "masks": "no", "key_frames": "no", "names": "no",
           "truth": "no", "methods": "mk-planes"}
    workflow_copy.write_scenes([{"scene": "phone", "camera": "focal35=26", **row},
                                {"scene": "known", "camera": "focal=1375.5,refine", **row},
                                {"scene": "plain", **row}])
    plan = workflow_copy.dry_run()
    assert "--max-features 4096 --no-progress" in plan.scene_jobs("plain")["poses"][0]
    assert " --focal" not in plan.scene_jobs("plain")["poses"][0]
    assert "--focal-35mm 26 --threads 1" in plan.scene_jobs("phone")["poses"][0]
    assert "--focal 1375.5 --refine-focal --threads 1" in plan.scene_jobs("known")["poses"][0]
    ready = tmp_path / "ready"
    ready.mkdir()
    workflow_copy.write_scenes([{"scene": "ready", "source": "dataset", "path": ready, "poses": "given",
                                 "camera": "focal=500"},
                                {"scene": "zero", "camera": "focal35=0", **row},
                                {"scene": "typo", "camera": "focal=26mm", **row}])
    run = workflow_copy.snakemake("-n", "--cores", "1")
    assert run.code != 0
    assert "line 2 (scene 'ready'): column 'camera': 'focal=500' is a focal length for COLMAP, which runs only " \
        "for poses 'estimate'" in run.output
    assert "line 3 (scene 'zero'): column 'camera': 'focal35=0' is not a positive focal length" in run.output
    assert "line 4 (scene 'typo'): key 'camera'" in run.output
