"""transforms.json as nerfstudio reads it: image paths from the file's folder, split lists, applied_transform,
ply_file_path, and camera_model honoured (fisheye refused) by this project's reader.

``tests/nerfstudio_mirror.py`` re-states nerfstudio's dataparser field handling; where nerfstudio itself is
importable (it is not a dependency of this project) its own dataparser reads the same folders.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from nerfstudio_mirror import read_like_nerfstudio

from stages.poses.model_export import relative_file_path
from stages.scene import SceneDataset, SceneError, read_scene, write_scene


def _edit(root: Path, fn) -> Path:
    path = root / "transforms.json"
    data = json.loads(path.read_text())
    fn(data)
    path.write_text(json.dumps(data))
    return path


def test_dataset_carries_nerfstudio_split_lists(tiny_dataset: SceneDataset) -> None:
    data = json.loads((tiny_dataset.root / "transforms.json").read_text())
    train = [f.file_path for f in tiny_dataset.frames if f.split == "train"]
    test = [f.file_path for f in tiny_dataset.frames if f.split == "test"]
    assert data["train_filenames"] == train and data["test_filenames"] == test
    assert data["val_filenames"] == test  # ns-train evaluates on "val" and fails when the list is missing
    assert data["applied_transform"] == np.eye(4)[:3].tolist()
    assert "split" in data["frames"][0]  # the per-frame key stays for this project's reader
    view = read_like_nerfstudio(tiny_dataset.root)
    root = tiny_dataset.root
    assert view.splits == {"train": [root / p for p in sorted(train)], "val": [root / p for p in sorted(test)],
                           "test": [root / p for p in sorted(test)]}
    assert view.camera_type == "PERSPECTIVE" and view.intrinsics[0]["fl_y"] == tiny_dataset.camera.fy


def test_split_lists_alone_give_the_split(tiny_dataset: SceneDataset) -> None:
    """A nerfstudio dataset has no per-frame split: the lists are read instead."""
    def drop_frame_split(data: dict) -> None:
        for frame in data["frames"]:
            del frame["split"]
        data["test_filenames"] = ["./" + p for p in data.pop("test_filenames")]  # same path, other spelling
        del data["val_filenames"]
    _edit(tiny_dataset.root, drop_frame_split)
    back = read_scene(tiny_dataset.root, deep=True)
    assert [f.split for f in back.frames] == [f.split for f in tiny_dataset.frames]


def test_split_lists_that_disagree_are_refused(tiny_dataset: SceneDataset) -> None:
    first = tiny_dataset.frames[0].file_path  # a test frame
    _edit(tiny_dataset.root, lambda d: d["train_filenames"].append(first))
    with pytest.raises(SceneError, match=r"frame_00000.png is in both train_filenames and val_filenames.*fix:"):
        read_scene(tiny_dataset.root)

    def move_to_train(data: dict) -> None:
        for key in ("val_filenames", "test_filenames"):
            data[key].remove(first)
    _edit(tiny_dataset.root, move_to_train)
    with pytest.raises(SceneError, match=r"has split 'test' but is listed in train_filenames.*fix:"):
        read_scene(tiny_dataset.root)
    write_scene(tiny_dataset)
    _edit(tiny_dataset.root, lambda d: d["test_filenames"].append("images/frame_00099.png"))
    with pytest.raises(SceneError, match=r"test_filenames names 1 image\(s\) that no frame has.*fix:"):
        read_scene(tiny_dataset.root)


def test_applied_transform_and_point_cloud_survive_a_round_trip(tiny_dataset: SceneDataset) -> None:
    applied = [[0.0, 1.0, 0.0, 0.5], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 2.0]]  # ns-process-data's kind
    (tiny_dataset.root / "sparse_pc.ply").write_text("ply\n")
    _edit(tiny_dataset.root, lambda d: d.update(applied_transform=applied, ply_file_path="sparse_pc.ply"))
    ds = read_scene(tiny_dataset.root, deep=True)
    write_scene(ds)  # e.g. a stage rewriting the metadata
    data = json.loads((tiny_dataset.root / "transforms.json").read_text())
    assert data["applied_transform"] == applied and data["ply_file_path"] == "sparse_pc.ply"
    assert read_like_nerfstudio(tiny_dataset.root).ply_file == tiny_dataset.root / "sparse_pc.ply"
    (tiny_dataset.root / "sparse_pc.ply").unlink()
    with pytest.raises(SceneError, match=r"ply_file_path 'sparse_pc.ply' names no file.*fix:"):
        read_scene(tiny_dataset.root)
    _edit(tiny_dataset.root, lambda d: (d.pop("ply_file_path"), d.update(applied_transform=[[1, 0], [0, 1]])))
    with pytest.raises(SceneError, match=r"applied_transform has shape \(2, 2\).*fix:"):
        read_scene(tiny_dataset.root)


@pytest.mark.parametrize("model", ["OPENCV_FISHEYE", "EQUIRECTANGULAR", "FISHEYE624"])
def test_non_pinhole_camera_models_are_refused(tiny_dataset: SceneDataset, model: str) -> None:
    _edit(tiny_dataset.root, lambda d: d.update(camera_model=model, k1=0.1, k2=0.01, k3=0.0, k4=0.0))
    with pytest.raises(SceneError, match=rf"camera_model {model} is not supported.*fix: undistort the images"):
        read_scene(tiny_dataset.root)


def test_camera_model_is_checked_with_per_frame_intrinsics(tiny_dataset: SceneDataset) -> None:
    def per_frame(data: dict) -> None:
        shared = {k: data.pop(k) for k in ("fl_x", "fl_y", "cx", "cy", "w", "h")}
        for frame in data["frames"]:
            frame.update(shared)
        data["camera_model"] = "OPENCV_FISHEYE"
    _edit(tiny_dataset.root, per_frame)
    with pytest.raises(SceneError, match=r"top level: camera_model OPENCV_FISHEYE"):
        read_scene(tiny_dataset.root)
    _edit(tiny_dataset.root, lambda d: d.update(camera_model="KANNALA"))
    with pytest.raises(SceneError, match=r"unknown camera_model 'KANNALA'.*fix: write one of SIMPLE_PINHOLE"):
        read_scene(tiny_dataset.root)
    _edit(tiny_dataset.root, lambda d: d.update(camera_model="PINHOLE"))
    assert read_scene(tiny_dataset.root).frames[0].camera.fx == tiny_dataset.camera.fx  # type: ignore[union-attr]


@pytest.mark.parametrize(("fields", "expected"), [
    ({"camera_model": "SIMPLE_RADIAL", "k1": 0.05}, {"k1": 0.05}),
    ({"camera_model": "RADIAL", "k1": 0.05, "k2": -0.02}, {"k1": 0.05, "k2": -0.02}),
    ({"camera_model": "OPENCV", "k1": 0.05, "k2": -0.02, "p1": 0.001, "p2": -0.002},
     {"k1": 0.05, "k2": -0.02, "p1": 0.001, "p2": -0.002}),
    ({"camera_model": "OPENCV", "distortion_params": [0.05, 0.0, 0.0, 0.0, 0.001, 0.0]}, {"k1": 0.05, "p1": 0.001}),
    ({"camera_model": "PINHOLE"}, {}),
    ({}, {}),  # no camera_model: perspective, as nerfstudio assumes
])
def test_perspective_models_read_their_coefficients(tiny_dataset: SceneDataset, fields: dict,
                                                    expected: dict) -> None:
    _edit(tiny_dataset.root, lambda d: (d.pop("camera_model", None), d.update(fields)))
    ds = read_scene(tiny_dataset.root)
    assert ds.camera.distortion == expected
    assert read_like_nerfstudio(tiny_dataset.root).camera_type == "PERSPECTIVE"


def test_paths_relative_to_the_file_resolve(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    """A POSES-like folder beside the images: file_path ../frames/images/..., read by both readers."""
    results = tmp_path / "results" / "scene"
    (results / "frames").mkdir(parents=True)
    os.replace(tiny_dataset.root / "images", results / "frames" / "images")
    poses = results / "poses"
    poses.mkdir()
    assert relative_file_path(results / "frames" / "images" / "frame_00001.png", poses) == \
        "../frames/images/frame_00001.png"
    data = json.loads((tiny_dataset.root / "transforms.json").read_text())
    for key in ("train_filenames", "val_filenames", "test_filenames"):
        data[key] = ["../frames/" + p for p in data[key]]
    for frame in data["frames"]:
        frame["file_path"] = "../frames/" + frame["file_path"]
    (poses / "transforms.json").write_text(json.dumps(data))
    ds = read_scene(poses, deep=True)
    assert [f.frame_id for f in ds.frames] == [f.frame_id for f in tiny_dataset.frames]
    assert all(ds.image_path(f).is_file() for f in ds.frames)
    view = read_like_nerfstudio(poses)
    assert all(p.is_file() for p in view.image_filenames) and len(view.splits["train"]) == 3


def test_nerfstudio_dataparser_reads_the_dataset(tiny_dataset: SceneDataset) -> None:
    """nerfstudio's own parser, where it can be imported (not a dependency: its CUDA stack is not installed)."""
    parsers = pytest.importorskip("nerfstudio.data.dataparsers.nerfstudio_dataparser")
    for split, expected in (("train", "train"), ("val", "test"), ("test", "test")):
        parser = parsers.NerfstudioDataParserConfig(data=tiny_dataset.root).setup()
        out = parser.get_dataparser_outputs(split=split)
        names = sorted(Path(p).name for p in out.image_filenames)
        assert names == sorted(Path(f.file_path).name for f in tiny_dataset.frames if f.split == expected)
        assert all(Path(p).is_file() for p in out.image_filenames)
        assert float(out.cameras.fy[0]) == pytest.approx(tiny_dataset.camera.fy)


def test_frames_of_two_cameras_are_written_so_that_nerfstudio_reads_each_frames_own(tiny_dataset: SceneDataset):
    """nerfstudio takes a top-level intrinsic key over the frame's: the writer keeps at the top level only what every
    frame shares, and both readers then give each frame its camera."""
    from dataclasses import replace

    ds = read_scene(tiny_dataset.root)
    other = replace(ds.camera, fx=ds.camera.fx * 1.5, fy=ds.camera.fy * 1.5)
    for f in ds.frames[::2]:
        f.camera = other
    write_scene(ds)
    data = json.loads((tiny_dataset.root / "transforms.json").read_text())
    assert "fl_x" not in data and data["w"] == ds.camera.width and "w" not in data["frames"][0]
    again = read_scene(tiny_dataset.root, deep=True)
    view = read_like_nerfstudio(tiny_dataset.root)
    ns_fx = {str(p.relative_to(tiny_dataset.root)): i["fl_x"] for p, i in zip(view.image_filenames, view.intrinsics,
                                                                              strict=True)}
    for k, f in enumerate(again.frames):
        expected = other.fx if k % 2 == 0 else tiny_dataset.camera.fx
        assert (f.camera or again.camera).fx == pytest.approx(expected)
        assert ns_fx[f.file_path] == pytest.approx(expected)


def test_per_frame_focal_lengths_with_one_size_at_the_top_level_are_read(tiny_dataset: SceneDataset) -> None:
    def per_frame(d: dict) -> None:
        for f in d["frames"]:
            f.update({k: d[k] for k in ("fl_x", "fl_y", "cx", "cy")})
        for k in ("fl_x", "fl_y", "cx", "cy"):
            d.pop(k)

    _edit(tiny_dataset.root, per_frame)
    ds = read_scene(tiny_dataset.root, deep=True)
    assert all(f.camera == tiny_dataset.camera for f in ds.frames) and ds.camera == tiny_dataset.camera
    assert read_like_nerfstudio(tiny_dataset.root).intrinsics[0]["fl_x"] == tiny_dataset.camera.fx


def test_a_windows_path_is_named_and_mask_path_is_said_to_be_unread(tiny_dataset: SceneDataset) -> None:
    first = tiny_dataset.frames[0].file_path
    _edit(tiny_dataset.root, lambda d: d["frames"][0].update(file_path=".\\" + first.replace("/", "\\")))
    with pytest.raises(SceneError, match=r"is a Windows path .*fix: write the paths with '/'"):
        read_scene(tiny_dataset.root)
    _edit(tiny_dataset.root, lambda d: d["frames"][0].update(file_path=first, mask_path="masks/ignore.png"))
    with pytest.warns(UserWarning, match=r"1 frame\(s\) give nerfstudio's mask_path .* trains on every pixel"):
        read_scene(tiny_dataset.root)


def test_a_transforms_json_in_another_encoding_is_named(tiny_dataset: SceneDataset) -> None:
    path = tiny_dataset.root / "transforms.json"
    path.write_bytes(path.read_text().replace('"frames"', '"frames"', 1).encode("utf-8").replace(b"{", b"{\xff", 1))
    with pytest.raises(SceneError, match=r"is not UTF-8 text .*fix: save the file as UTF-8"):
        read_scene(tiny_dataset.root)


@pytest.mark.parametrize("name", ["../../esc", "a/b", "..", "back\\slash"])
def test_an_object_name_that_is_a_path_is_refused(tiny_dataset: SceneDataset, name: str) -> None:
    (tiny_dataset.root / "mapping.yaml").write_text(json.dumps({1: name, 2: "drawer"}))
    with pytest.raises(SceneError, match=r"object name .* fix: name the object in words"):
        read_scene(tiny_dataset.root)
