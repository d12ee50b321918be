"""COLMAP's cameras and quaternions in the contract's terms, checked against pycolmap's own projection and
hand-computed values (no structure from motion runs)."""

from __future__ import annotations

from pathlib import Path

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import open3d as o3d
import pycolmap
import pytest
from colmap_testdata import synthetic_model, write_model
from poses_testdata import orbit_poses
from scipy.spatial.transform import Rotation

from stages.dataset.triangulation import _colmap_params
from stages.poses import quaternion_wxyz_from_rotation
from stages.poses.model_export import SUPPORTED_CAMERA_MODELS, scene_box, scene_camera
from stages.poses.pose_sources import read_pose_set
from stages.scene import Camera, generate_rays
from stages.scene.transforms import camera_from_dict, camera_to_dict

# every parameter distinct, so that a swapped pair (fx/fy, cx/cy, p1/p2) moves the pixels
PARAMS = {"SIMPLE_PINHOLE": [100.0, 81.0, 58.0],
          "PINHOLE": [100.0, 92.0, 81.0, 58.0],
          "SIMPLE_RADIAL": [100.0, 81.0, 58.0, -0.05],
          "RADIAL": [100.0, 81.0, 58.0, -0.05, 0.02],
          "OPENCV": [100.0, 92.0, 81.0, 58.0, -0.05, 0.02, 0.004, -0.006]}
U = np.array([10, 40, 80, 120, 150, 30])
V = np.array([10, 100, 60, 20, 110, 60])


def _projected_by_colmap(colmap: pycolmap.Camera, camera: Camera) -> np.ndarray:
    """Where COLMAP's camera projects the contract camera's rays through pixels (U, V)."""
    _, dirs = generate_rays(camera, np.eye(4), U, V)
    return np.asarray(colmap.img_from_cam(dirs * np.array([1.0, -1.0, -1.0])))  # OpenGL -> OpenCV camera axes


@pytest.mark.parametrize("model", SUPPORTED_CAMERA_MODELS)
def test_the_exported_camera_casts_the_rays_that_colmap_s_camera_projects_onto_their_pixels(model: str) -> None:
    """COLMAP camera -> the contract's Camera -> transforms.json's intrinsics -> rays: COLMAP projects each ray back
    onto the centre of its pixel (both put pixel centres at +0.5), so no parameter was swapped or dropped."""
    assert model in PARAMS
    colmap = pycolmap.Camera.create_from_model_name(1, model, 100.0, 160, 120)
    colmap.params = PARAMS[model]
    exported = camera_from_dict(camera_to_dict(scene_camera(colmap)), Path("transforms.json"), "top level")
    assert (exported.width, exported.height) == (160, 120)
    np.testing.assert_allclose(_projected_by_colmap(colmap, exported), np.stack([U + 0.5, V + 0.5], -1), atol=1e-4)


def test_the_triangulation_camera_is_the_dataset_s_camera_in_colmap_s_opencv_order() -> None:
    """``dataset orient`` triangulates with an OPENCV camera made from the dataset's intrinsics: COLMAP's order is
    fx, fy, cx, cy, k1, k2, p1, p2 (its params_info), checked by projecting the dataset camera's rays."""
    camera = Camera(fx=100.0, fy=92.0, cx=81.0, cy=58.0, width=160, height=120,
                    distortion={"k1": -0.05, "k2": 0.02, "p1": 0.004, "p2": -0.006})
    colmap = pycolmap.Camera.create_from_model_name(1, "OPENCV", 1.0, 160, 120)
    assert colmap.params_info.replace(" ", "") == "fx,fy,cx,cy,k1,k2,p1,p2"
    colmap.params = _colmap_params(camera)
    np.testing.assert_allclose(_projected_by_colmap(colmap, camera), np.stack([U + 0.5, V + 0.5], -1), atol=1e-4)


def test_a_camera_with_k3_is_triangulated_with_colmap_s_full_opencv_model() -> None:
    """OPENCV has no k3: a dataset camera with one gets FULL_OPENCV, whose radial factor (1 + k1 r^2 + k2 r^4 +
    k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6) is OpenCV's polynomial with k4..k6 at 0; COLMAP then projects the
    dataset camera's rays back onto their pixels (with OPENCV, k3 dropped, the corner lands elsewhere)."""
    from stages.dataset.triangulation import _colmap_model

    camera = Camera(fx=100.0, fy=92.0, cx=81.0, cy=58.0, width=160, height=120,
                    distortion={"k1": -0.05, "k2": 0.02, "p1": 0.004, "p2": -0.006, "k3": 0.03})
    assert _colmap_model([camera]) == "FULL_OPENCV"
    assert _colmap_model([Camera(fx=100.0, fy=92.0, cx=81.0, cy=58.0, width=160, height=120,
                                 distortion={"k1": -0.05})]) == "OPENCV"
    colmap = pycolmap.Camera.create_from_model_name(1, "FULL_OPENCV", 1.0, 160, 120)
    assert colmap.params_info.replace(" ", "") == "fx,fy,cx,cy,k1,k2,p1,p2,k3,k4,k5,k6"
    colmap.params = _colmap_params(camera, "FULL_OPENCV")
    np.testing.assert_allclose(_projected_by_colmap(colmap, camera), np.stack([U + 0.5, V + 0.5], -1), atol=1e-4)
    opencv = pycolmap.Camera.create_from_model_name(1, "OPENCV", 1.0, 160, 120)
    opencv.params = _colmap_params(camera)
    assert np.abs(_projected_by_colmap(opencv, camera) - np.stack([U + 0.5, V + 0.5], -1)).max() > 1.0  # 1.24 px


def test_a_colmap_model_s_two_focal_lengths_are_read_for_the_pose_comparison(tmp_path: Path) -> None:
    camera = Camera(fx=100.0, fy=92.0, cx=81.0, cy=58.0, width=160, height=120)
    rec = synthetic_model([f"frame_{k:05d}.png" for k in range(4)], orbit_poses(4), camera=camera, model="PINHOLE",
                          n_points=40)
    read = read_pose_set(write_model(rec, tmp_path / "sparse" / "0")).camera
    assert (read.fx, read.fy, read.cx, read.cy, read.width, read.height) == (100.0, 92.0, 81.0, 58.0, 160, 120)


def test_the_quaternion_is_written_with_a_non_negative_w() -> None:
    """q and -q are one rotation; COLMAP's images.txt convention here is w >= 0. A turn of -170 degrees about x is
    q = (cos -85, sin -85, 0, 0) = (0.0872, -0.9962, 0, 0), whose largest component is negative."""
    q = quaternion_wxyz_from_rotation(Rotation.from_rotvec([np.radians(-170.0), 0.0, 0.0]).as_matrix())
    np.testing.assert_allclose(q, [np.cos(np.radians(85.0)), -np.sin(np.radians(85.0)), 0.0, 0.0], atol=1e-12)


def test_the_scene_box_holds_the_cameras_outside_the_points() -> None:
    """The model samples rays from the cameras: a camera at (5, -4, 0.5) outside the unit cube of points widens
    the box to x = 5 and y = -4."""
    rng = np.random.default_rng(0)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(rng.uniform(0.0, 1.0, (200, 3))))
    box, info = scene_box(cloud, np.array([[5.0, -4.0, 0.5]]))
    assert box[1][0] == 5.0 and box[0][1] == -4.0
    assert box[0][0] >= 0.0 and box[1][1] <= 1.0 and info["includes_camera_centres"]


def test_a_model_made_at_another_size_has_its_keypoints_scaled_per_axis(tmp_path: Path) -> None:
    """A model of 320x241 images imported for 160x120 frames (odd sizes round: 0.4 % apart, accepted as a resize):
    every keypoint moves to (x * 160 / 320, y * 120 / 241), each axis by its own factor."""
    from stages.poses.colmap_import import fit_cameras

    big = Camera(fx=200.0, fy=200.0, cx=160.0, cy=120.5, width=320, height=241)
    rec = synthetic_model([f"frame_{k:05d}.png" for k in range(4)], orbit_poses(4), camera=big, model="PINHOLE",
                          n_points=60)
    before = {i: np.array([p.xy for p in im.points2D]) for i, im in rec.images.items()}
    assert fit_cameras(rec, {1: (160, 120, "frame_00000.png")}, tmp_path) == {1: [0.5, 120 / 241]}
    for i, im in rec.images.items():
        np.testing.assert_allclose(np.array([p.xy for p in im.points2D]), before[i] * [0.5, 120 / 241], rtol=1e-12)
    assert (rec.cameras[1].width, rec.cameras[1].height) == (160, 120)


def test_the_export_records_no_world_change_after_the_colmap_model() -> None:
    """sparse/0 is written in the same (turned) world as transforms.json, so nerfstudio's applied_transform, the
    motion made after the COLMAP model, is the 3x4 identity; each frame's matrix is the OpenGL pose it was built
    from."""
    from stages.poses.model_export import transforms_dict

    poses = orbit_poses(4)
    rec = synthetic_model([f"frame_{k:05d}.png" for k in range(4)], poses, n_points=40)
    out = transforms_dict(rec, {})
    assert out["applied_transform"] == [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
    for frame, c2w in zip(out["frames"], poses, strict=True):
        np.testing.assert_allclose(frame["transform_matrix"], c2w, atol=1e-9)
