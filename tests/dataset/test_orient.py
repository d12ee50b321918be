"""`livescene dataset orient`: a ready dataset's copy in the upright, wall-aligned world (stages/dataset/orient.py)."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from stages.dataset.orient import axis_misalignment_deg, orient_dataset
from stages.scene import SceneDataset, SceneError, read_scene, write_scene


def _room_points(rng: np.random.Generator, n: int = 3000) -> np.ndarray:
    """Points on the floor, ceiling and walls of a 5 x 4 x 2.6 room centred at the origin (z up)."""
    size = np.array([5.0, 4.0, 2.6])
    faces = rng.integers(0, 6, n)
    pts = rng.uniform(0.0, 1.0, (n, 3)) * size
    axis, side = faces // 2, faces % 2
    pts[np.arange(n), axis] = side * size[axis]
    return pts - size / 2 + rng.normal(0.0, 0.01, (n, 3))


def _ready_dataset(ds: SceneDataset, old_from_room: np.ndarray, offset: np.ndarray, with_points: bool = True
                   ) -> Path:
    """The tiny dataset (cameras looking down at the room's centre) moved by a rigid motion, with its points."""
    root = ds.root
    move = np.eye(4)
    move[:3, :3], move[:3, 3] = old_from_room, offset
    for f in ds.frames:
        f.c2w = move @ f.c2w
    ds.scene_box = None
    ds.meta = {"units": "colmap"}
    if with_points:
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(_room_points(np.random.default_rng(0))))
        cloud.transform(move)
        o3d.io.write_point_cloud(str(root / "sparse_pc.ply"), cloud)
        ds.nerfstudio["ply_file_path"] = "sparse_pc.ply"
    write_scene(ds, root)
    return root


def _digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_a_tilted_dataset_comes_back_upright_and_untouched(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    old_from_room = Rotation.from_euler("xyz", [24.0, -11.0, 37.0], degrees=True).as_matrix()
    src = _ready_dataset(tiny_dataset, old_from_room, np.array([4.0, -2.0, 7.0]))
    before = _digest(src)
    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert _digest(src) == before

    assert how.turned and how.misalignment_deg > 20.0
    new_from_room = how.new_from_old[:3, :3] @ old_from_room
    assert axis_misalignment_deg(new_from_room) < 0.5
    assert new_from_room[2, 2] > np.cos(np.radians(0.5))  # z is up
    source = read_scene(src)
    for new, old in zip(ds.frames, source.frames, strict=True):
        np.testing.assert_allclose(new.c2w, how.new_from_old @ old.c2w, atol=1e-12)
        assert new.file_path == old.file_path and new.state == old.state and new.split == old.split
        assert np.array_equal(ds.load_image(new), source.load_image(old))
        assert np.array_equal(ds.load_mask(new), source.load_mask(old))
    # the box is the turned room's (about 5 x 4 x 2.6, not the tilted room's bounding box) and holds the cameras
    extent = np.sort(ds.scene_box[1] - ds.scene_box[0])
    assert extent[0] < 3.0 and extent[2] < 6.5
    centres = np.stack([f.c2w[:3, 3] for f in ds.frames])
    assert (centres >= ds.scene_box[0]).all() and (centres <= ds.scene_box[1]).all()
    # nerfstudio's record of the motion, the turned points next to the poses, the reason
    np.testing.assert_allclose(np.asarray(ds.nerfstudio["applied_transform"]), how.new_from_old[:3], atol=1e-12)
    turned = np.asarray(o3d.io.read_point_cloud(str(ds.root / ds.nerfstudio["ply_file_path"])).points)
    given = np.asarray(o3d.io.read_point_cloud(str(src / "sparse_pc.ply")).points)
    np.testing.assert_allclose(turned, given @ how.new_from_old[:3, :3].T + how.new_from_old[:3, 3], atol=1e-9)
    assert ds.meta["orientation"]["turned"] and ds.meta["orientation"]["from"] == str(src)
    assert ds.objects == source.objects and ds.key_frames == source.key_frames and ds.prompts == source.prompts


def test_an_upright_dataset_keeps_its_world(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    quarter = Rotation.from_euler("z", 90.0, degrees=True).as_matrix()  # axes relabelled, still on the walls
    src = _ready_dataset(tiny_dataset, quarter, np.zeros(3))
    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert not how.turned and "already within" in how.reason
    assert np.array_equal(how.new_from_old, np.eye(4))
    for new, old in zip(ds.frames, read_scene(src).frames, strict=True):
        assert np.array_equal(new.c2w, old.c2w)


def test_an_upright_dataset_without_a_box_gets_the_box_of_its_points(tiny_dataset: SceneDataset,
                                                                    tmp_path: Path) -> None:
    """A published set (rendered upright, no scene.json) keeps its world but not the box around its cameras alone,
    which leaves out the walls the cameras face: the box holds the points (the 5 x 4 x 2.6 room, turned a quarter
    about z: x within 2.0, y within 2.5, z within 1.3 of the centre) and the cameras."""
    quarter = Rotation.from_euler("z", 90.0, degrees=True).as_matrix()
    src = _ready_dataset(tiny_dataset, quarter, np.zeros(3))
    assert read_scene(src).scene_box is None
    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert not how.turned
    centres = np.stack([f.c2w[:3, 3] for f in ds.frames])
    room = np.array([2.0, 2.5, 1.3])
    np.testing.assert_allclose(ds.scene_box[0], np.minimum(-room, centres.min(0)), atol=0.05)
    np.testing.assert_allclose(ds.scene_box[1], np.maximum(room, centres.max(0)), atol=0.05)
    assert "points, grown to include the camera centres" in ds.meta["scene_box_rule"]

    given = read_scene(src)  # a box the dataset brings is kept where its world is
    given.scene_box = np.array([[-9.0, -9.0, -9.0], [9.0, 9.0, 9.0]])
    write_scene(given, src)
    ds, how = orient_dataset(src, tmp_path / "oriented-own-box")
    assert not how.turned and np.array_equal(ds.scene_box, given.scene_box)


def test_without_points_the_world_is_kept_with_the_reason(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    tilt = Rotation.from_euler("x", 30.0, degrees=True).as_matrix()
    src = _ready_dataset(tiny_dataset, tilt, np.zeros(3), with_points=False)
    ds, how = orient_dataset(src, tmp_path / "oriented", triangulate=False)
    assert not how.turned and "no point cloud" in how.reason and how.frame is None
    assert ds.meta["orientation"]["turned"] is False
    for new, old in zip(ds.frames, read_scene(src).frames, strict=True):
        assert np.array_equal(new.c2w, old.c2w)


def test_bad_points_are_refused_and_nothing_is_written(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    src = _ready_dataset(tiny_dataset, np.eye(3), np.zeros(3), with_points=False)
    with pytest.raises(SceneError, match="point cloud not found"):
        orient_dataset(src, tmp_path / "oriented", points=tmp_path / "none.ply")
    (tmp_path / "empty.ply").write_text("not a ply\n")
    with pytest.raises(SceneError, match="no points could be read") as err:
        orient_dataset(src, tmp_path / "oriented", points=tmp_path / "empty.ply")
    assert "empty.ply" in str(err.value)
    with pytest.raises(SceneError, match="the dataset itself"):
        orient_dataset(src, src)
    assert not (tmp_path / "oriented").exists()


def test_cli_says_what_it_did(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    src = _ready_dataset(tiny_dataset, Rotation.from_euler("y", 20.0, degrees=True).as_matrix(), np.zeros(3))
    out = tmp_path / "oriented"
    run = subprocess.run([sys.executable, "-m", "stages.cli", "dataset", "orient", "--data", str(src), "--out",
                          str(out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert "turned upright" in run.stdout and "6 frames" in run.stdout
    bad = subprocess.run([sys.executable, "-m", "stages.cli", "dataset", "orient", "--data", str(src), "--out",
                          str(tmp_path / "x"), "--points", str(tmp_path / "none.ply")], capture_output=True, text=True)
    assert bad.returncode == 2 and "none.ply" in bad.stderr and "point cloud not found" in bad.stderr


def test_images_outside_the_dataset_are_brought_into_the_copy(tiny_dataset: SceneDataset, tmp_path: Path) -> None:
    """A transforms.json may name images beside its folder (`../frames/images/...`, as a POSES folder does)."""
    src = _ready_dataset(tiny_dataset, Rotation.from_euler("x", 25.0, degrees=True).as_matrix(), np.zeros(3))
    outside = tmp_path / "shared_images"
    (src / "images").rename(outside)
    data = json.loads((src / "transforms.json").read_text())
    for frame in data["frames"]:
        frame["file_path"] = "../shared_images/" + Path(frame["file_path"]).name
    data.pop("train_filenames"), data.pop("val_filenames"), data.pop("test_filenames")
    (src / "transforms.json").write_text(json.dumps(data))
    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert how.turned
    assert [f.file_path for f in ds.frames] == [f"images/{Path(p['file_path']).name}" for p in data["frames"]]
    assert all(ds.image_path(f).is_file() and ds.image_path(f).parent == ds.root / "images" for f in ds.frames)


def test_the_axis_misalignment_is_that_of_the_worst_axis() -> None:
    """A turn of 20 degrees about z leaves z on its axis and moves x and y 20 degrees off theirs: the dataset is
    20 degrees off (not 0: a turn about one axis would otherwise read as aligned and never be undone)."""
    assert axis_misalignment_deg(Rotation.from_euler("z", 20.0, degrees=True).as_matrix()) == pytest.approx(20.0)


def test_a_turn_composes_onto_the_applied_transform_already_recorded(tiny_dataset: SceneDataset,
                                                                    tmp_path: Path) -> None:
    """nerfstudio's applied_transform maps the original world to the poses' world; turning them again by M maps
    the original world by M @ applied, so a viewer can still undo both."""
    old_from_room = Rotation.from_euler("xyz", [24.0, -11.0, 37.0], degrees=True).as_matrix()
    applied = np.eye(4)
    applied[:3, :3] = Rotation.from_euler("x", -90.0, degrees=True).as_matrix()  # ns-process-data's kind of record
    applied[:3, 3] = [0.5, 0.0, -1.0]
    tiny_dataset.nerfstudio["applied_transform"] = applied[:3].tolist()
    src = _ready_dataset(tiny_dataset, old_from_room, np.array([4.0, -2.0, 7.0]))
    ds, how = orient_dataset(src, tmp_path / "oriented")
    assert how.turned
    np.testing.assert_allclose(np.asarray(ds.nerfstudio["applied_transform"]), (how.new_from_old @ applied)[:3],
                               atol=1e-12)


def test_a_camera_with_nerfstudios_k4_is_triangulated_with_a_warning_that_names_the_file(
        tiny_dataset: SceneDataset) -> None:
    """No COLMAP model has nerfstudio's r^8 term: the triangulation says so before it runs COLMAP (the warning
    raised as an error here, so COLMAP does not run)."""
    import dataclasses
    import warnings

    from stages.dataset.triangulation import triangulate_dataset

    ds = dataclasses.replace(tiny_dataset, camera=dataclasses.replace(tiny_dataset.camera, distortion={"k4": 1e-4}))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match=r"transforms\.json: COLMAP has no model with the r\^8 coefficient k4"):
            triangulate_dataset(ds)
