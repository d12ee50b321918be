"""Evaluation on a REAL (tiny) run: a generated capture, its truth dataset, a few LiveScene steps with the language
table, then `livescene evaluate` against the capture's truth renderer at half resolution.

Quality cannot be asserted after a few steps; what is checked is that every part runs on the real model API and
that the numbers are consistent with the renders written next to them.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from tiny_language_run import BagOfWordsEncoder, train_tiny_language_run

from stages.evaluate import cli as evaluate_cli
from stages.evaluate.metrics import psnr
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES
from stages.scene import read_scene

ROOT = Path(__file__).resolve().parents[2]
TINY_MODEL = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=100", "train.eval_rays=64",
    "train.checkpoint_every=100", "train.render_chunk=1024", "train.threads=1", "train.max_steps=4",
]


@pytest.fixture(scope="module")
def real_run(tmp_path_factory):
    """(capture, dataset, run) of a 64x48, 8-frame capture of the tiny preset, trained 4 steps with language."""
    return train_tiny_language_run(tmp_path_factory.mktemp("real_run"), TINY_MODEL)


def test_evaluate_a_real_run_against_the_truth_renderer(real_run, tmp_path, monkeypatch, capsys):
    capture, data, run = real_run
    monkeypatch.setattr("stages.language.cli.encoder_from_args", lambda args: BagOfWordsEncoder())
    out = tmp_path / "eval"
    # the tiny capture's 4 training frames never hold an object near 0.5, and every novel vector needs one there:
    # every level is allowed here, so that the unseen path runs (the default's record is checked below)
    code = evaluate_cli.main(["--run", str(run), "--data", str(data), "--truth", str(capture), "--out", str(out),
                              "--max-views", "2", "--unseen-views", "1", "--scale", "0.5", "--observed-within", "-1"])
    assert code == 0
    headline = json.loads(capsys.readouterr().out)
    metrics = json.loads((out / "metrics.json").read_text())
    ds = read_scene(data)

    held = metrics["held_out"]
    assert held["image_size"] == [32, 24] and held["psnr"]["n"] == 2 and held["lpips_status"].startswith("not")
    timings = json.loads((out / "timings.json").read_text())
    assert timings["held_out"]["fps"] > 0 and headline["fps"] == pytest.approx(timings["held_out"]["fps"])
    assert timings["machine"]["cpu"] and "torch_cpu_capability" in timings["machine"]  # what the fps was measured on
    assert headline["psnr"] == pytest.approx(held["psnr"]["mean"])
    # the per-view PSNR is that of the PNG written for the report against the area-downscaled dataset image
    view = held["views"][0]
    frame = next(f for f in ds.frames if f.frame_id == view["frame"])
    render = cv2.imread(str(out / "renders" / f"{view['frame']}.png"))[..., ::-1] / 255.0
    gt = cv2.resize(ds.load_image(frame), (32, 24), interpolation=cv2.INTER_AREA)
    assert psnr(render, gt) == pytest.approx(view["psnr"], abs=0.1)

    unseen = metrics["unseen_combinations"]
    assert unseen["status"] == "computed" and unseen["truth_pose_source"] == ["source_index"]
    assert unseen["n_unseen"] >= 1 and unseen["seen_reference"]["psnr"]["n"] == 1
    assert unseen["observed_within"] is None and unseen["levels_not_observed"] == {}
    for rec in unseen["records"]:
        if not rec["rendered"]:  # too close to a training state: listed, not rendered
            assert not rec["unseen"] and rec["psnr"] is None
            continue
        assert rec["moved_objects"] and rec["moved_pixels"] > 0 and np.isfinite(rec["psnr_moved"])

    ground = metrics["grounding"]
    assert ground["status"] == "computed" and ground["sources"] == ["probs", "language", "language_objects"]
    names = {q["query"] for q in ground["queries"] if q["kind"] == "name"}
    assert names == {n.replace("_", " ") for n in ds.objects}
    assert {q["kind"] for q in ground["queries"]} == {"name", "synonym"}
    printed = headline["grounding_per_query"]
    assert len(printed) == len(ground["queries"]) and all(set(v) == set(ground["sources"]) for v in printed.values())
    maps = sorted((out / "grounding").glob("*.png"))
    assert maps and all(cv2.imread(str(p), cv2.IMREAD_UNCHANGED).shape == (24, 32) for p in maps)


def test_unseen_levels_the_capture_never_showed_are_named(real_run, tmp_path, capsys):
    capture, data, run = real_run
    out = tmp_path / "eval"
    assert evaluate_cli.main(["--run", str(run), "--data", str(data), "--truth", str(capture), "--out", str(out),
                              "--max-views", "1", "--unseen-views", "1", "--scale", "0.5", "--no-grounding",
                              "--locality-views", "0", "--no-renders"]) == 0
    unseen = json.loads((out / "metrics.json").read_text())["unseen_combinations"]
    # training holds the cabinet at 0, 0.89 and 0.33, the drawer at 0, 0.03 and 1: neither near 0.5
    assert unseen["observed_within"] == 0.125
    assert unseen["levels_not_observed"] == {"cabinet": [0.5], "drawer": [0.5]}
    assert unseen["training_range"]["drawer"] == [0.0, 1.0]
    assert all(0.5 not in c["values"] for c in unseen["combinations"]) and unseen["n_unseen"] == 0


def test_scale_outside_0_1_is_refused(real_run, tmp_path, capsys):
    _, data, run = real_run
    assert evaluate_cli.main(["--run", str(run), "--data", str(data), "--out", str(tmp_path / "e"), "--scale", "2",
                              "--no-grounding"]) == 2
    assert "--scale" in capsys.readouterr().err and not (tmp_path / "e").exists()


def test_max_side_scores_at_an_integer_fraction_of_the_dataset_size(real_run, tmp_path):
    """--max-side 40 on 64x48 frames: factor 2 (32x24), recorded as the render scale; 64 keeps the full size."""
    _, data, run = real_run
    for max_side, size, scale in ((40, [32, 24], 0.5), (64, [64, 48], 1.0)):
        out = tmp_path / str(max_side)
        assert evaluate_cli.main(["--run", str(run), "--data", str(data), "--out", str(out), "--max-views", "1",
                                  "--no-grounding", "--no-renders", "--max-side", str(max_side)]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["held_out"]["image_size"] == size and metrics["config"]["render_scale"] == scale


@pytest.mark.parametrize("extra, named", [(["--max-side", "40", "--scale", "0.5"], "--scale"),
                                          (["--max-side", "8"], "at least 16")])
def test_max_side_refusals_name_the_flag(real_run, tmp_path, capsys, extra, named):
    _, data, run = real_run
    assert evaluate_cli.main(["--run", str(run), "--data", str(data), "--out", str(tmp_path / "e"), "--no-grounding",
                              *extra]) == 2
    err = capsys.readouterr().err
    assert "--max-side" in err and named in err and not (tmp_path / "e").exists()


def test_metrics_of_a_real_run_are_identical_between_evaluations(real_run, tmp_path, monkeypatch):
    """The real model renders deterministically on the CPU and every wall-clock number is in timings.json."""
    capture, data, run = real_run
    monkeypatch.setattr("stages.language.cli.encoder_from_args", lambda args: BagOfWordsEncoder())
    outs = [tmp_path / "a", tmp_path / "b"]
    for out in outs:
        assert evaluate_cli.main(["--run", str(run), "--data", str(data), "--truth", str(capture), "--out", str(out),
                                  "--max-views", "2", "--unseen-views", "1", "--scale", "0.5"]) == 0
    assert (outs[0] / "metrics.json").read_bytes() == (outs[1] / "metrics.json").read_bytes()
    assert all(json.loads((o / "timings.json").read_text())["held_out"]["render_seconds"] > 0 for o in outs)


def test_a_truth_capture_of_other_objects_is_refused(real_run, tmp_path, capsys):
    capture, data, run = real_run
    other = tmp_path / "other"  # the same capture but for its object names: another room's, as far as names go
    other.mkdir()
    (other / "mapping.yaml").write_text("1: fridge\n2: oven\n")
    for item in capture.iterdir():
        if not (other / item.name).exists():
            (other / item.name).symlink_to(item.resolve())
    code = evaluate_cli.main(["--run", str(run), "--data", str(data), "--truth", str(other), "--out",
                              str(tmp_path / "eval"), "--no-grounding"])
    assert code == 2
    err = capsys.readouterr().err
    assert "the truth capture's objects ['fridge', 'oven'] are not the dataset's" in err and "fix: pass --truth" in err
    assert not (tmp_path / "eval").exists()
