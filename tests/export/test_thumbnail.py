"""The thumbnail's ray caster on scenes whose pixels are known: colours, shading, misses, the view it takes."""

from __future__ import annotations

import cv2
import numpy as np
import open3d as o3d
import pytest

from stages.export.thumbnail import AMBIENT, overview_view, raycast_mesh, write_thumbnail
from stages.scene import Camera

ONE_RAY = Camera(fx=1.0, fy=1.0, cx=0.5, cy=0.5, width=1, height=1)
"""One pixel whose ray runs along the camera's -z axis."""


def _above(x: float, y: float) -> np.ndarray:
    """An OpenGL camera 2 above (x, y, 0) looking straight down (-z)."""
    c2w = np.eye(4)
    c2w[:3, 3] = [x, y, 2.0]
    return c2w


def _triangle(vertices, colours) -> o3d.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(np.asarray(vertices, float)),
        o3d.utility.Vector3iVector(np.array([[0, 1, 2]], np.int32)),
    )
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.asarray(colours, float))
    return mesh


def test_a_pixel_shows_the_interpolated_vertex_colour_of_a_surface_facing_it():
    # red, green, blue corners; (0.3, 0.1) = 0.6 A + 0.3 B + 0.1 C; the normal (+z) faces the ray head on
    mesh = _triangle([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.eye(3))
    pixel = raycast_mesh(mesh, ONE_RAY, _above(0.3, 0.1))[0, 0]
    assert pixel == pytest.approx([0.6, 0.3, 0.1], abs=1e-5)
    # the same triangle wound the other way (normal -z) looks the same: shading ignores which side is hit
    flipped = _triangle([[0, 0, 0], [0, 1, 0], [1, 0, 0]], [[1, 0, 0], [0, 0, 1], [0, 1, 0]])
    assert raycast_mesh(flipped, ONE_RAY, _above(0.3, 0.1))[0, 0] == pytest.approx([0.6, 0.3, 0.1], abs=1e-5)


def test_a_surface_seen_at_60_degrees_is_shaded_and_a_miss_is_white():
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.array([0.0, np.cos(np.radians(60)), -np.sin(np.radians(60))])  # the plane's normal is 60 deg from z
    grey = _triangle([-5 * e1 - 5 * e2, 5 * e1 - 5 * e2, 5 * e2], np.full((3, 3), 0.8))
    shade = AMBIENT + (1.0 - AMBIENT) * 0.5  # cos 60 = 0.5
    assert raycast_mesh(grey, ONE_RAY, _above(0.0, 0.0))[0, 0] == pytest.approx([0.8 * shade] * 3, abs=1e-5)
    assert raycast_mesh(grey, ONE_RAY, _above(100.0, 100.0))[0, 0].tolist() == [1.0, 1.0, 1.0]


def test_the_thumbnail_takes_the_middle_pose_with_a_wider_view_and_is_written_as_rgb(tmp_path):
    camera = Camera(fx=50.0, fy=50.0, cx=32.0, cy=24.0, width=64, height=48)
    poses = [_above(float(i), 0.0) for i in range(5)]
    cam, pose = overview_view(camera, poses, width=320)
    assert cam == Camera(fx=50.0 * 5 / 1.6, fy=50.0 * 5 / 1.6, cx=160.0, cy=120.0, width=320, height=240)
    assert np.array_equal(pose, poses[2])
    red = _triangle([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[1.0, 0.0, 0.0]] * 3)
    write_thumbnail(tmp_path / "t.png", red, ONE_RAY, _above(0.3, 0.1))
    assert cv2.imread(str(tmp_path / "t.png"))[0, 0].tolist() == [0, 0, 255]  # OpenCV reads BGR: red
