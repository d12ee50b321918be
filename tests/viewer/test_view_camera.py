"""Camera conventions between viser (OpenCV axes, quaternions, vertical fov) and the run API (OpenGL 4x4)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stages.scene import Camera, generate_rays, look_at
from stages.viewer.view_camera import (
    ViewPose,
    frustum_scale,
    look_at_point,
    rotation_to_wxyz,
    scene_up,
    vertical_fov,
    viser_pose,
    wxyz_to_rotation,
)


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


def test_quaternions_round_trip_for_any_rotation():
    rng = np.random.default_rng(0)
    rotations = [_random_rotation(rng) for _ in range(200)]
    rotations += [np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]), np.diag([-1.0, -1.0, 1.0]), np.eye(3)]
    for rot in rotations:
        q = rotation_to_wxyz(rot)
        assert abs(np.linalg.norm(q) - 1.0) < 1e-12 and q[0] >= 0
        assert np.allclose(wxyz_to_rotation(q), rot, atol=1e-10)


def test_a_training_pose_goes_to_viser_and_back_unchanged():
    c2w = look_at(np.array([2.0, -1.0, 1.5]), np.array([0.0, 0.5, 0.3]))
    wxyz, position = viser_pose(c2w)
    view = ViewPose.from_viser(wxyz, position, fov_y=0.9, aspect=4 / 3)
    assert np.allclose(view.c2w, c2w, atol=1e-10)


def test_viser_gets_opencv_axes_looking_at_the_target():
    eye, target = np.array([2.0, -1.0, 1.5]), np.array([0.0, 0.5, 0.3])
    wxyz, position = viser_pose(look_at(eye, target))
    rot = wxyz_to_rotation(wxyz)
    towards = (target - eye) / np.linalg.norm(target - eye)
    assert np.allclose(position, eye)
    assert np.allclose(rot[:, 2], towards, atol=1e-10)  # OpenCV: +z looks forward
    assert rot[:, 1] @ np.array([0.0, 0.0, 1.0]) < 0  # +y points down in the image of an upright camera


def test_the_view_camera_has_the_clients_vertical_fov():
    view = ViewPose(np.eye(4), fov_y=math.radians(60), aspect=16 / 9)
    cam = view.camera(160, 90)
    assert cam.width == 160 and cam.height == 90 and cam.fx == cam.fy
    assert vertical_fov(cam) == pytest.approx(math.radians(60))
    # the rays through the top and bottom edges span the fov
    _, dirs = generate_rays(cam, np.eye(4), u=np.array([79.5, 79.5]), v=np.array([-0.5, 89.5]))
    assert math.acos(float(dirs[0] @ dirs[1])) == pytest.approx(math.radians(60), abs=1e-9)
    dataset_camera = Camera(fx=200.0, fy=200.0, cx=128, cy=96, width=256, height=192)
    assert vertical_fov(dataset_camera) == pytest.approx(2 * math.atan(96 / 200))


def test_same_view_compares_pose_fov_and_aspect():
    a = ViewPose(np.eye(4), 1.0, 1.5)
    moved = np.eye(4)
    moved[0, 3] = 1e-3
    assert a.same_view(ViewPose(np.eye(4), 1.0, 1.5))
    assert not a.same_view(ViewPose(moved, 1.0, 1.5))
    assert not a.same_view(ViewPose(np.eye(4), 1.1, 1.5))
    assert not a.same_view(None)


def test_scene_up_is_level_with_the_cameras_whatever_the_convention():
    # a quarter orbit looking down at a table: the mean of the cameras' up axes leans towards the table
    arc = np.linspace(0.0, np.pi / 2, 12)
    eyes = [np.array([3 * np.cos(t), 3 * np.sin(t), 1.5]) for t in arc]
    z_up = [look_at(e, np.array([0.0, 0.0, 0.2])) for e in eyes]
    mean_up = np.mean([c[:3, 1] for c in z_up], axis=0)
    assert mean_up[2] / np.linalg.norm(mean_up) < 0.95  # biased by about 20 degrees
    assert np.allclose(scene_up(z_up), [0, 0, 1], atol=1e-9)
    # the same cameras in a y-up world (as another tool could write them)
    swap = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])  # z -> y, a rotation
    assert np.allclose(scene_up([swap @ c for c in z_up]), [0, 1, 0], atol=1e-9)
    # a straight dolly (every right axis parallel) falls back on the mean up axis
    dolly = [look_at(np.array([x, -3.0, 1.0]), np.array([x, 0.0, 1.0])) for x in np.linspace(-1, 1, 5)]
    assert np.allclose(scene_up(dolly), [0, 0, 1], atol=1e-9)
    assert np.allclose(scene_up([]), [0, 0, 1])


def test_frustums_are_about_the_spacing_of_the_cameras():
    line = np.stack([np.array([0.1 * i, 0.0, 0.0]) for i in range(50)])  # 0.1 apart, 4.9 long
    assert frustum_scale(line) == pytest.approx(0.2)
    sparse = np.array([[0.0, 0, 0], [10.0, 0, 0]])
    assert frustum_scale(sparse) == pytest.approx(0.5)  # 5 % of the spread at most
    assert frustum_scale(np.zeros((1, 3))) == 0.1


def test_the_orbit_point_lies_on_the_viewing_axis():
    c2w = look_at(np.array([0.0, -3.0, 0.0]), np.zeros(3))
    assert np.allclose(look_at_point(c2w, np.array([0.5, 0.0, 0.2])), [0.0, 0.0, 0.0], atol=1e-9)
    behind = look_at_point(c2w, np.array([0.0, -5.0, 0.0]))
    assert np.linalg.norm(behind - c2w[:3, 3]) == pytest.approx(1e-3)


def test_frustums_of_a_dense_cluster_keep_one_percent_of_the_spread():
    cluster = [np.array([0.001 * i, 0.0, 0.0]) for i in range(50)]  # a camera held still, then one far away
    assert frustum_scale(np.stack([*cluster, np.array([10.0, 0.0, 0.0])])) == pytest.approx(0.1)  # 1 % of 10


def test_a_camera_rolled_upside_down_converts_without_losing_precision():
    """Half a turn about z and 1e-7 rad about y: x's diagonal term beats y's, z's is the largest. Branching on the
    largest term keeps the square root away from 0 (x's branch would take sqrt(~1e-14): errors of 1e-9)."""
    t = 1e-7
    tilt = np.array([[math.cos(t), 0.0, math.sin(t)], [0.0, 1.0, 0.0], [-math.sin(t), 0.0, math.cos(t)]])
    rot = np.diag([-1.0, -1.0, 1.0]) @ tilt
    assert np.allclose(wxyz_to_rotation(rotation_to_wxyz(rot)), rot, rtol=0.0, atol=1e-12)


def test_same_view_tells_another_aspect_apart():
    assert not ViewPose(np.eye(4), 1.0, 1.5).same_view(ViewPose(np.eye(4), 1.0, 16 / 9))
