"""transforms.json axis convention: a truth pose goes to COLMAP's convention and back unchanged."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest
from poses_testdata import SMALL_CAMERA, orbit_poses
from scipy.spatial.transform import Rotation

from stages.poses import (
    c2w_opengl_from_cam_from_world,
    cam_from_world_from_c2w_opengl,
    quaternion_wxyz_from_rotation,
    rotation_angle_deg,
    rotation_from_quaternion_wxyz,
)
from stages.scene import look_at, project_points


@pytest.mark.parametrize("c2w", [*orbit_poses(5), look_at(np.array([1.0, -2.0, 0.4]), np.array([0.0, 0.5, 1.9]))])
def test_truth_pose_round_trips_through_colmap_convention(c2w: np.ndarray) -> None:
    rotation, translation = cam_from_world_from_c2w_opengl(c2w)
    # through the quaternion COLMAP writes in images.txt (w, x, y, z) and pycolmap's own (x, y, z, w)
    q = quaternion_wxyz_from_rotation(rotation)
    np.testing.assert_allclose(np.abs(q), np.abs(np.roll(pycolmap.Rotation3d(rotation).quat, 1)), atol=1e-12)
    back = c2w_opengl_from_cam_from_world(rotation_from_quaternion_wxyz(q), translation)
    np.testing.assert_allclose(back, c2w, atol=1e-12)


def test_colmap_projects_like_the_opengl_pose() -> None:
    """COLMAP (world -> OpenCV camera -> pixels) and the contract's projection agree on every point."""
    c2w = orbit_poses(3)[1]
    rotation, translation = cam_from_world_from_c2w_opengl(c2w)
    cam_from_world = pycolmap.Rigid3d(rotation=pycolmap.Rotation3d(rotation), translation=translation)
    camera = pycolmap.Camera(model="PINHOLE", width=SMALL_CAMERA.width, height=SMALL_CAMERA.height,
                             params=[SMALL_CAMERA.fx, SMALL_CAMERA.fy, SMALL_CAMERA.cx, SMALL_CAMERA.cy])
    # points in front of the camera: along its -z (OpenGL viewing direction), spread sideways
    rng = np.random.default_rng(0)
    local = np.column_stack([rng.uniform(-0.5, 0.5, 20), rng.uniform(-0.4, 0.4, 20), -rng.uniform(1, 3, 20)])
    world = local @ c2w[:3, :3].T + c2w[:3, 3]
    in_camera = world @ np.asarray(cam_from_world.rotation.matrix()).T + np.asarray(cam_from_world.translation)
    assert (in_camera[:, 2] > 0).all()  # COLMAP's camera looks down +z
    colmap_uv = camera.img_from_cam(in_camera)
    ours, depth = project_points(SMALL_CAMERA, c2w, world)
    np.testing.assert_allclose(colmap_uv, ours, atol=1e-9)
    np.testing.assert_allclose(depth, in_camera[:, 2], atol=1e-12)


def test_rotation_angle() -> None:
    a = orbit_poses(2)[0][:3, :3]
    turn = Rotation.from_rotvec([0.0, np.radians(7.0), 0.0]).as_matrix()
    assert rotation_angle_deg(a, a @ turn) == pytest.approx(7.0, abs=1e-9)
    assert rotation_angle_deg(a, a) == pytest.approx(0.0, abs=1e-6)


def test_axis_misalignment_is_zero_for_relabelled_axes_and_the_angle_otherwise():
    from stages.poses.conventions import axis_misalignment_deg

    swap = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])  # x->y->z->x: relabelling only
    assert axis_misalignment_deg(swap) == pytest.approx(0.0, abs=1e-9)
    for deg in (3.0, 17.0, 40.0):  # one turn about z: the nearest relabelling is within 45 degrees of it
        turned = Rotation.from_euler("z", deg, degrees=True).as_matrix()
        assert axis_misalignment_deg(swap @ turned) == pytest.approx(min(deg, 90.0 - deg), abs=1e-6)
