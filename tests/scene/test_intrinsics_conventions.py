"""transforms.json reading against conventions fixed outside this project: OpenCV's distortion model (which
COLMAP's OPENCV camera and nerfstudio's OPENCV camera share), the defaults an image's size implies, rigid poses."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.scene import Camera, SceneError, generate_rays
from stages.scene.transforms import camera_from_dict, parse_pose


@pytest.mark.parametrize("coeffs", [
    {"k2": -0.08},
    {"p2": 0.01},
    {"k3": 0.05},
    {"k1": -0.1, "k2": 0.03, "p1": 0.004, "p2": -0.006, "k3": 0.01},
])
def test_the_rays_of_a_distorted_camera_project_back_onto_their_pixels_through_opencv(coeffs: dict) -> None:
    """A ray through pixel (u, v), projected with cv2.projectPoints and the same coefficients, lands on the pixel's
    centre (u + 0.5, v + 0.5): each coefficient is inverted with OpenCV's meaning of it."""
    cam = Camera(fx=100.0, fy=95.0, cx=81.0, cy=58.0, width=160, height=120, distortion=coeffs)
    u = np.array([10, 40, 80, 120, 150, 30])
    v = np.array([10, 100, 60, 20, 110, 60])
    _, dirs = generate_rays(cam, np.eye(4), u, v)
    in_opencv_axes = dirs * np.array([1.0, -1.0, -1.0])  # OpenGL (y up, looking down -z) -> OpenCV (y down, +z)
    dist = np.array([coeffs.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3")])  # OpenCV's order
    uv, _ = cv2.projectPoints(in_opencv_axes, np.zeros(3), np.zeros(3), cam.K, dist)
    np.testing.assert_allclose(uv[:, 0], np.stack([u + 0.5, v + 0.5], axis=-1), atol=1e-4)


def test_a_principal_point_left_out_is_the_image_centre() -> None:
    """nerfstudio form with only fl_x, w, h: fy = fx (square pixels), (cx, cy) = (w / 2, h / 2) of a 160x120 image."""
    cam = camera_from_dict({"fl_x": 100.0, "w": 160, "h": 120}, Path("transforms.json"), "top level")
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (100.0, 100.0, 80.0, 60.0, 160, 120)


def test_a_mirrored_pose_is_refused() -> None:
    """diag(1, 1, -1) is orthonormal but a reflection (determinant -1): no rigid camera has it."""
    with pytest.raises(SceneError, match=r"frames\[0\].*not orthonormal"):
        parse_pose(np.diag([1.0, 1.0, -1.0, 1.0]).tolist(), Path("transforms.json"), "frames[0]")


def test_a_blender_camera_with_its_size_given_keeps_width_and_height_apart() -> None:
    """camera_angle_x = 90 degrees across a 20-pixel-wide, 10-pixel-high image: f = (20 / 2) / tan(45) = 10."""
    cam = camera_from_dict({"camera_angle_x": np.pi / 2, "w": 20, "h": 10}, Path("transforms.json"), "top level")
    assert (cam.width, cam.height, cam.cx, cam.cy) == (20, 10, 10.0, 5.0)
    assert cam.fx == pytest.approx(10.0) and cam.fy == pytest.approx(10.0)
