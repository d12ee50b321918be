"""Round trips of the scene dataset contract and both transforms.json forms."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np

from stages.scene import make_split, read_scene
from stages.scene.normalization import apply_similarity_to_points, apply_similarity_to_pose, box_to_unit_transform


def test_round_trip_is_bit_exact(tiny_dataset, tmp_path):
    back = read_scene(tiny_dataset.root, deep=True)
    assert back.objects == tiny_dataset.objects
    assert back.object_ids == tiny_dataset.object_ids
    assert back.camera == tiny_dataset.camera
    assert [f.frame_id for f in back.frames] == [f.frame_id for f in tiny_dataset.frames]
    for a, b in zip(tiny_dataset.frames, back.frames, strict=True):
        assert np.array_equal(a.c2w, b.c2w)  # float64 survives JSON exactly
        assert a.state == b.state
        assert a.split == b.split
        assert a.source_index == b.source_index
    assert back.key_frames == tiny_dataset.key_frames
    assert back.prompts == tiny_dataset.prompts
    assert np.array_equal(back.scene_box, tiny_dataset.scene_box)
    for f in back.frames:
        mask = back.load_mask(f)
        again = np.load(tiny_dataset.root / "masks" / f"{f.frame_id}.npy")
        assert mask.dtype == bool and mask.shape == (12, 16, 4)
        assert np.array_equal(mask, again)
        assert mask.sum(-1).max() == 1  # one-hot
    np.testing.assert_array_equal(back.state_matrix(), tiny_dataset.state_matrix())


def test_blender_form_is_read(tmp_path: Path):
    root = tmp_path / "blender"
    (root / "images").mkdir(parents=True)
    cv2.imwrite(str(root / "images" / "r_0.png"), np.zeros((10, 20, 3), np.uint8))
    cv2.imwrite(str(root / "images" / "r_1.png"), np.zeros((10, 20, 3), np.uint8))
    c2w = np.eye(4).tolist()
    data = {"camera_angle_x": math.radians(90), "frames": [
        {"file_path": "./images/r_0", "transform_matrix": c2w},
        {"file_path": "./images/r_1", "transform_matrix": c2w},
    ]}
    (root / "transforms.json").write_text(json.dumps(data))
    ds = read_scene(root)
    assert (ds.camera.width, ds.camera.height) == (20, 10)
    assert math.isclose(ds.camera.fx, 10.0)  # tan(45 deg) = 1 -> f = w / 2
    assert [f.frame_id for f in ds.frames] == ["0", "1"]
    assert ds.image_path(ds.frames[0]).name == "r_0.png"


def test_nerfstudio_per_frame_intrinsics_override(tiny_dataset):
    path = tiny_dataset.root / "transforms.json"
    data = json.loads(path.read_text())
    data["frames"][1].update({"fl_x": 99.0, "fl_y": 98.0, "cx": 8.0, "cy": 6.0, "w": 16, "h": 12})
    path.write_text(json.dumps(data))
    ds = read_scene(tiny_dataset.root)
    assert ds.camera_of(ds.frames[1]).fx == 99.0
    assert ds.camera_of(ds.frames[0]).fx == 20.0


def test_splits():
    assert make_split(4, "alternate") == ["test", "train", "test", "train"]
    every = make_split(20, "every_n", n=5)
    assert [i for i, s in enumerate(every) if s == "test"] == [2, 7, 12, 17]
    frac = make_split(100, "fraction", test_fraction=0.1)
    assert frac.count("test") == 10
    assert make_split(1, "alternate") == ["train"]


def test_normalisation_maps_box_to_unit_cube_and_keeps_poses_rigid():
    lo, hi = np.array([2.0, -1.0, 0.0]), np.array([6.0, 1.0, 3.0])
    t = box_to_unit_transform(lo, hi)
    corners = apply_similarity_to_points(t, np.array([lo, hi]))
    assert np.all(corners >= -1 - 1e-12) and np.all(corners <= 1 + 1e-12)
    assert np.isclose(np.max(corners[1] - corners[0]), 2.0)
    pose = np.eye(4)
    pose[:3, 3] = [4.0, 0.0, 1.5]
    moved = apply_similarity_to_pose(t, pose)
    np.testing.assert_allclose(moved[:3, :3], np.eye(3))
    np.testing.assert_allclose(moved[:3, 3], apply_similarity_to_points(t, pose[:3, 3]))


def test_an_image_of_another_size_is_named_when_loaded(tiny_dataset, tmp_path):
    import shutil

    import pytest

    from stages.scene import SceneError

    root = tmp_path / "ds"
    shutil.copytree(tiny_dataset.root, root)
    ds = read_scene(root)  # the shallow check does not open images
    frame = ds.frames[3]
    cv2.imwrite(str(ds.image_path(frame)), np.zeros((24, 32, 3), np.uint8))
    with pytest.raises(SceneError, match=r"image is 32x24 but transforms\.json says 16x12.*--deep"):
        ds.load_image(frame)
