"""Ray generation and projection against hand-computed pinhole cases."""

from __future__ import annotations

import numpy as np

from stages.scene import Camera, generate_rays, opencv_to_opengl, opengl_to_opencv, project_points


def test_pinhole_rays_hand_computed():
    cam = Camera(fx=100.0, fy=50.0, cx=2.0, cy=1.0, width=4, height=2)
    c2w = np.eye(4)
    c2w[:3, 3] = [1.0, 2.0, 3.0]
    origins, dirs = generate_rays(cam, c2w)
    assert dirs.shape == (2, 4, 3)
    np.testing.assert_allclose(origins[0, 0], [1.0, 2.0, 3.0])
    # pixel (u=0, v=0): centre at (0.5, 0.5) -> x = (0.5 - 2) / 100, y = (0.5 - 1) / 50, OpenGL flips y, looks -z
    expected = np.array([-1.5 / 100, 0.5 / 50, -1.0])
    np.testing.assert_allclose(dirs[0, 0], expected / np.linalg.norm(expected))
    # pixel (u=3, v=1)
    expected = np.array([1.5 / 100, -0.5 / 50, -1.0])
    np.testing.assert_allclose(dirs[1, 3], expected / np.linalg.norm(expected))


def test_rotated_camera_and_projection_round_trip():
    cam = Camera(fx=80.0, fy=80.0, cx=32.0, cy=24.0, width=64, height=48)
    angle = np.radians(30)
    c2w = np.eye(4)
    c2w[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    c2w[:3, 3] = [0.3, -0.2, 2.0]
    u = np.array([0, 10, 63])
    v = np.array([0, 20, 47])
    origins, dirs = generate_rays(cam, c2w, u, v)
    points = origins + 3.0 * dirs
    uv, depth = project_points(cam, c2w, points)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], -1), atol=1e-9)
    assert np.all(depth > 0)


def test_distortion_is_inverted():
    cam = Camera(fx=100.0, fy=100.0, cx=50.0, cy=50.0, width=100, height=100, distortion={"k1": -0.1, "p1": 0.01})
    _, dirs = generate_rays(cam, np.eye(4), np.array([5]), np.array([90]))
    x, y = dirs[0, 0] / -dirs[0, 2], -dirs[0, 1] / -dirs[0, 2]  # back to OpenCV normalised coords
    r2 = x * x + y * y
    xd = x * (1 - 0.1 * r2) + 2 * 0.01 * x * y
    yd = y * (1 - 0.1 * r2) + 0.01 * (r2 + 2 * y * y)
    np.testing.assert_allclose([xd * 100 + 50, yd * 100 + 50], [5.5, 90.5], atol=1e-6)


def test_axis_flip_is_its_own_inverse():
    m = np.arange(16, dtype=float).reshape(4, 4)
    np.testing.assert_array_equal(opencv_to_opengl(opengl_to_opencv(m)), m)
