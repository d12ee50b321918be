"""livescene poses on a rendered room: outputs, accuracy against the true poses, masks kept out of SIFT."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pycolmap
import pytest
from poses_testdata import SMALL_CAMERA

from stages.poses import PosesConfig, compare_poses, estimate_poses
from stages.poses.conventions import axis_misalignment_deg
from stages.poses.sfm import extract_features
from stages.scene import Camera, write_json
from stages.scene.transforms import camera_to_dict

Room = tuple[Path, Path, Camera, list[np.ndarray]]


@pytest.fixture(scope="module")
def room_poses(room_sequence: Room, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root, masks, _camera, _poses = room_sequence
    out = tmp_path_factory.mktemp("poses") / "poses"
    estimate_poses(PosesConfig(frames_dir=root, out_dir=out, masks_dir=masks, threads=2, seed=0,
                               keep_database=True, progress=False))
    return out


def test_outputs_follow_the_contract(room_poses: Path, room_sequence: Room) -> None:
    names = sorted(p.name for p in (room_sequence[0] / "images").iterdir())
    summary = json.loads((room_poses / "poses.json").read_text())
    assert summary["registered_fraction"] == 1.0 and summary["unregistered"] == []
    assert summary["registered"] == names and summary["matcher"] == "exhaustive"
    assert summary["mean_reprojection_error"] < 1.0 and summary["n_points3D"] > 100
    assert {"extract", "match", "map", "total"} <= set(summary["timings"])
    assert summary["masks"]["frames_with_masks"] == len(names) and summary["warnings"] == []
    # the 70-degree arc turns the view: the focal length is constrained (docs/poses.md, "Known focal length")
    check = summary["focal_check"]
    assert check["focal"] == "estimated" and check["poorly_constrained"] is False and check["n_cameras"] == len(names)
    assert check["axis_spread_deg"] > check["warn_below_deg"]
    assert {p.name for p in (room_poses / "sparse" / "0").iterdir()} >= {"cameras.bin", "images.bin",
                                                                          "points3D.bin"}
    assert not (room_poses / "colmap_work").exists()
    transforms = json.loads((room_poses / "transforms.json").read_text())
    # relative to the poses folder, so nerfstudio finds the frames' images from there
    assert [f["file_path"] for f in transforms["frames"]] == [
        os.path.relpath(room_sequence[0] / "images" / n, room_poses) for n in names]
    assert all((room_poses / f["file_path"]).is_file() for f in transforms["frames"])
    assert [f["source_index"] for f in transforms["frames"]] == list(range(len(names)))
    assert transforms["w"] == SMALL_CAMERA.width and transforms["h"] == SMALL_CAMERA.height
    cloud = o3d.io.read_point_cloud(str(room_poses / "points3D.ply"))
    assert len(cloud.points) == summary["n_points3D"]
    box = np.asarray(json.loads((room_poses / "scene.json").read_text())["scene_box"])
    centres = np.array([f["transform_matrix"] for f in transforms["frames"]])[:, :3, 3]
    assert (centres >= box[0]).all() and (centres <= box[1]).all()


def test_poses_match_the_truth(room_poses: Path, room_sequence: Room, tmp_path: Path) -> None:
    """The whole convention chain: wrong axes or a transposed rotation would give errors of tens of degrees."""
    _root, _masks, camera, poses = room_sequence
    truth = tmp_path / "truth" / "transforms.json"
    write_json(truth, {**camera_to_dict(camera), "frames": [
        {"file_path": f"images/frame_{i:05d}.png", "transform_matrix": p.tolist()} for i, p in enumerate(poses)]})
    report = compare_poses(room_poses / "transforms.json", truth, extent=4.0)  # the room is 4 x 3 x 2.5 m
    assert report["n_matched"] == len(poses)
    assert report["centre_error_relative"]["mean"] < 0.01
    assert report["rotation_error_deg"]["mean"] < 1.0
    assert report["focal_error"]["relative_fx"] < 0.03


def keypoints_by_name(database: Path) -> dict[str, np.ndarray]:
    db = pycolmap.Database.open(database)
    try:
        return {image.name: db.read_keypoints(image_id=image.image_id)[:, :2] for image in db.read_all_images()}
    finally:
        db.close()


def on_objects(keypoints: np.ndarray, mask_png: Path) -> int:
    """How many keypoints (COLMAP pixel coordinates, centre of the first pixel at 0.5) fall on an object."""
    ids = cv2.imread(str(mask_png), cv2.IMREAD_UNCHANGED)
    col = np.clip(np.floor(keypoints[:, 0]).astype(int), 0, ids.shape[1] - 1)
    row = np.clip(np.floor(keypoints[:, 1]).astype(int), 0, ids.shape[0] - 1)
    return int(np.count_nonzero(ids[row, col] == 1))


def test_masked_objects_get_no_features(room_poses: Path, room_sequence: Room, tmp_path: Path) -> None:
    root, masks, _camera, _poses = room_sequence
    masked = keypoints_by_name(room_poses / "database.db")
    # the same frames without masks: the crate does carry features, so the check below can fail
    database = tmp_path / "unmasked.db"
    names = sorted(masked)[:4]
    extract_features(PosesConfig(frames_dir=root, out_dir=tmp_path, threads=2), database, root / "images", names,
                     None)
    unmasked = keypoints_by_name(database)
    assert sum(on_objects(unmasked[n], masks / n) for n in names) > 20
    for name, keypoints in masked.items():
        assert len(keypoints) > 50
        assert on_objects(keypoints, masks / name) == 0, name


def test_world_is_turned_to_the_room(room_poses: Path, room_sequence: Room, tmp_path: Path) -> None:
    """The axis-aligned truth room comes out axis-aligned (COLMAP's own world is at an arbitrary angle)."""
    _root, _masks, camera, poses = room_sequence
    truth = tmp_path / "truth" / "transforms.json"
    write_json(truth, {**camera_to_dict(camera), "frames": [
        {"file_path": f"images/frame_{i:05d}.png", "transform_matrix": p.tolist()} for i, p in enumerate(poses)]})
    report = compare_poses(room_poses / "transforms.json", truth, extent=4.0)
    sim3 = np.asarray(report["sim3"])
    rotation = sim3[:3, :3] / np.cbrt(np.linalg.det(sim3[:3, :3]))
    assert report["axes_misalignment_deg"] == pytest.approx(axis_misalignment_deg(rotation)) and \
        report["axes_misalignment_deg"] < 2.0
    frame = json.loads((room_poses / "poses.json").read_text())["world_frame"]
    assert frame == json.loads((room_poses / "scene.json").read_text())["world_frame"]
    assert np.asarray(frame["new_from_old"]).shape == (3, 4)
    # sparse/0 was turned with the exported poses: its camera centres are transforms.json's
    rec = pycolmap.Reconstruction(room_poses / "sparse" / "0")
    by_name = {img.name: img for img in rec.images.values()}
    transforms = json.loads((room_poses / "transforms.json").read_text())
    for f in transforms["frames"]:
        image = by_name[Path(f["file_path"]).name]
        centre = image.projection_center()
        np.testing.assert_allclose(centre, np.asarray(f["transform_matrix"])[:3, 3], atol=1e-6)
