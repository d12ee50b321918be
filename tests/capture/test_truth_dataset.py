"""`livescene capture dataset`: a scene dataset straight from a capture's truth."""

from __future__ import annotations

import json

import cv2
import numpy as np

from stages.capture.cli import main
from stages.scene import read_scene, validate_scene


def test_capture_dataset_validates_and_matches_the_truth(tiny_capture, tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(["dataset", "--capture", str(tiny_capture), "--out", str(out), "--no-progress"]) == 0
    ds = read_scene(out, validate=True, deep=True)
    validate_scene(ds, deep=True)
    truth = json.loads((tiny_capture / "truth" / "transforms.json").read_text())["frames"]
    assert len(ds.frames) == len(truth)
    assert ds.objects == ["cabinet", "drawer"]
    assert [f.split for f in ds.frames[:4]] == ["test", "train", "test", "train"]
    for f, t in zip(ds.frames, truth, strict=True):
        assert f.source_index == t["source_index"]
        np.testing.assert_allclose(f.c2w, np.asarray(t["transform_matrix"]))
        assert f.state == t["state"]
    ids = cv2.imread(str(tiny_capture / "masks" / "frame_00003.png"), cv2.IMREAD_UNCHANGED)
    mask = ds.load_mask(ds.frames[3])
    for channel in range(2):
        assert np.array_equal(mask[..., channel], ids == channel + 1)
    assert np.array_equal(mask[..., 2], ids == 0)
    assert mask.any(axis=(0, 1))[:2].all(), "both objects should be visible in frame 3"
    assert set(ds.key_frames) == {"00000", "00005", "00007"}
    assert ds.scene_box is not None and ds.scene_box.shape == (2, 3)


def test_capture_dataset_every_n_drops_frames_and_their_key_frames(tiny_capture, tmp_path):
    out = tmp_path / "ds"
    assert main(["dataset", "--capture", str(tiny_capture), "--out", str(out), "--every", "2",
                 "--images", "truth", "--no-progress"]) == 0
    ds = read_scene(out)
    assert [f.source_index for f in ds.frames] == [0, 2, 4, 6]
    assert set(ds.key_frames) == {"00000"}


def test_capture_dataset_refuses_to_clobber(tiny_capture, tmp_path, capsys):
    out = tmp_path / "ds"
    out.mkdir()
    (out / "keep.txt").write_text("mine")
    assert main(["dataset", "--capture", str(tiny_capture), "--out", str(out), "--no-progress"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "mine"


def test_a_room_without_objects_gives_a_dataset_without_masks(small_spec, tmp_path):
    """A static room (no movable objects) is a valid dataset: no masks, no mapping (masks need a mapping)."""
    from stages.capture import capture_to_dataset, generate_capture

    spec = small_spec(n_frames=4)
    spec.objects = []
    capture = generate_capture(spec, tmp_path / "capture", progress=False)
    ds = capture_to_dataset(capture, tmp_path / "ds", progress=False)
    validate_scene(read_scene(tmp_path / "ds"), deep=True)
    assert ds.objects == [] and len(ds.frames) == 4 and not (tmp_path / "ds" / "masks").exists()


def test_masks_and_states_are_left_out_as_a_room_filmed_without_them(tiny_capture, tmp_path):
    """A sheet row with `masks: no` / `key_frames: no`: the truth's masks and states are not the row's."""
    common = ["dataset", "--capture", str(tiny_capture), "--images", "truth", "--no-progress"]
    assert main([*common, "--out", str(tmp_path / "nomasks"), "--no-masks"]) == 0
    ds = read_scene(tmp_path / "nomasks")
    assert ds.objects and not ds.has_masks and all(f.state for f in ds.frames)
    assert main([*common, "--out", str(tmp_path / "nostates"), "--no-states"]) == 0
    ds = read_scene(tmp_path / "nostates")
    assert ds.has_masks and not ds.key_frames and all(f.state is None for f in ds.frames)
    assert main([*common, "--out", str(tmp_path / "static"), "--no-masks", "--no-states"]) == 0
    ds = read_scene(tmp_path / "static")
    assert ds.objects == [] and not ds.key_frames and not ds.prompts and not ds.has_masks
    assert ds.meta["source"]["left_out"] == ["masks", "states"]
