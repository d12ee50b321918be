"""A distorted camera in both directions: pixels -> rays undo the distortion, points -> pixels apply it (as
``cv2.projectPoints``), strong barrel distortion is inverted to the pixel, and a camera whose distortion folds inside
its image is refused (docs/data-contract.md, "Lens distortion")."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from stages.scene import Camera, SceneError, generate_rays, project_points
from stages.scene import camera as camera_module
from stages.scene.camera import distortion_fold, undistort_normalized
from stages.scene.transforms import camera_from_dict


def _turned_pose() -> np.ndarray:
    angle = np.radians(25)
    c2w = np.eye(4)
    c2w[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    c2w[:3, 3] = [0.4, -0.3, 1.5]
    return c2w


def test_points_project_through_the_distortion_as_opencv_projects_them() -> None:
    """project_points of a distorted camera equals cv2.projectPoints with the same coefficients and pose."""
    coeffs = {"k1": -0.12, "k2": 0.03, "p1": 0.002, "p2": -0.003, "k3": 0.01}
    cam = Camera(fx=300.0, fy=290.0, cx=161.0, cy=119.0, width=320, height=240, distortion=coeffs)
    c2w = _turned_pose()
    rng = np.random.default_rng(0)
    cam_points = np.c_[rng.uniform(-1, 1, (20, 2)), -rng.uniform(2, 4, 20)]  # in front of the camera (OpenGL -z)
    world = cam_points @ c2w[:3, :3].T + c2w[:3, 3]
    uv, depth = project_points(cam, c2w, world)
    w2c = np.linalg.inv(c2w)
    w2c_cv = np.diag([1.0, -1.0, -1.0]) @ w2c[:3]  # OpenGL camera -> OpenCV camera (y down, z forward)
    rvec, _ = cv2.Rodrigues(w2c_cv[:, :3])
    dist = np.array([coeffs.get(k, 0.0) for k in ("k1", "k2", "p1", "p2", "k3")])
    expected, _ = cv2.projectPoints(world, rvec, w2c_cv[:, 3], cam.K, dist)
    np.testing.assert_allclose(uv, expected[:, 0], atol=1e-9)
    np.testing.assert_allclose(depth, -cam_points[:, 2], atol=1e-12)


@pytest.mark.parametrize(
    "coeffs", [{"k1": -0.1}, {"k1": -0.3, "k2": 0.05}, {"k1": -0.3, "k2": 0.05, "p1": 0.01, "p2": -0.01}, {"k1": 0.3}]
)
def test_the_ray_through_a_distorted_pixel_projects_back_onto_it(coeffs: dict) -> None:
    """Every corner and a spread of pixels of a 640x480 image at fx = 512: the ray through the pixel, 3 units out,
    projects to the pixel's centre. At k1 = -0.3, k2 = 0.05 OpenCV's fixed-point iteration (10 rounds) ends 0.2 px
    off at the corner; the inverse must reach the pixel to 1e-6 px."""
    cam = Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480, distortion=coeffs)
    u = np.array([0, 639, 0, 639, 320, 100, 600, 17])
    v = np.array([0, 0, 479, 479, 240, 400, 30, 250])
    c2w = _turned_pose()
    origins, dirs = generate_rays(cam, c2w, u, v)
    uv, _ = project_points(cam, c2w, origins + 3.0 * dirs)
    np.testing.assert_allclose(uv, np.stack([u + 0.5, v + 0.5], -1), atol=1e-6)


def test_strong_barrel_distortion_is_inverted_where_the_fixed_point_iteration_stalls() -> None:
    """At the 640x480 image's corner (fx = 512: xd = -0.624, yd = -0.468) with k1 = -0.3, k2 = 0.05, ten
    fixed-point rounds leave a residual of about 0.2 px (their contraction factor 2 |k1| r^2 / (1 + k1 r^2) is near
    0.6); the inverse distorts back onto the corner."""
    cam = Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.3, "k2": 0.05})
    xd, yd = np.array([(0.5 - 320) / 512]), np.array([(0.5 - 240) / 512])
    x, y = xd.copy(), yd.copy()
    for _ in range(10):  # OpenCV's fixed point, as undistort_normalized used to stop
        r2 = x * x + y * y
        x, y = xd / (1 - 0.3 * r2 + 0.05 * r2**2), yd / (1 - 0.3 * r2 + 0.05 * r2**2)
    r2 = x * x + y * y
    fixed_point_miss = 512 * np.hypot(x * (1 - 0.3 * r2 + 0.05 * r2**2) - xd, y * (1 - 0.3 * r2 + 0.05 * r2**2) - yd)
    assert fixed_point_miss[0] > 0.1  # the failure this guards against is real at this corner
    x, y = undistort_normalized(cam, xd, yd)
    r2 = x * x + y * y
    radial = 1 - 0.3 * r2 + 0.05 * r2**2
    np.testing.assert_allclose([x * radial, y * radial], [xd, yd], atol=1e-12)


def test_a_camera_without_distortion_never_enters_the_inverse(monkeypatch: pytest.MonkeyPatch) -> None:
    """A pinhole camera's rays are the pinhole arithmetic alone (the demo's bits): the inverse is not called."""

    def refuse(*_: object) -> None:
        raise AssertionError("undistort_normalized called for a pinhole camera")

    monkeypatch.setattr(camera_module, "undistort_normalized", refuse)
    cam = Camera(fx=100.0, fy=100.0, cx=2.0, cy=1.0, width=4, height=2, distortion={"k1": 0.0})
    _, dirs = generate_rays(cam, np.eye(4))
    expected = np.array([-1.5 / 100, 0.5 / 100, -1.0])
    np.testing.assert_allclose(dirs[0, 0], expected / np.linalg.norm(expected))


def test_a_scaled_camera_keeps_its_coefficients_and_projects_to_scaled_pixels() -> None:
    """The coefficients act on normalised coordinates, so a half-size image has the same ones: a point projecting
    to (u, v) in the 640x480 camera projects to (u / 2, v / 2) in the 320x240 one."""
    cam = Camera(fx=512.0, fy=500.0, cx=321.0, cy=239.0, width=640, height=480, distortion={"k1": -0.2, "p2": 0.004})
    half = cam.scaled(0.5)
    assert half.distortion == cam.distortion and (half.width, half.height) == (320, 240)
    world = np.array([[0.3, -0.2, -2.0], [-0.9, 0.6, -1.5], [0.0, 0.0, -3.0]])
    full_uv, _ = project_points(cam, np.eye(4), world)
    half_uv, _ = project_points(half, np.eye(4), world)
    np.testing.assert_allclose(half_uv, full_uv / 2, atol=1e-12)


def test_a_distortion_that_folds_inside_the_image_is_found() -> None:
    """k1 = -0.3 alone: r (1 - 0.3 r^2) peaks at r = 1 / sqrt(0.9) = 1.054 with 2 / (3 sqrt(0.9)) = 0.703, and the
    640x480 image's corner at fx = 512 is 0.78 focal lengths out: no ray reaches it. At fx = 640 the corner is 0.625
    out and every pixel has its ray; k2 = 0.05 balances the fold away at fx = 512."""
    folded = Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.3})
    assert "(0.5, 0.5) is the image of no ray" in (distortion_fold(folded) or "")
    assert (
        distortion_fold(Camera(fx=640.0, fy=640.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.3}))
        is None
    )
    assert (
        distortion_fold(
            Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.3, "k2": 0.05})
        )
        is None
    )
    assert distortion_fold(Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480)) is None


def test_a_camera_that_folds_back_onto_another_branch_is_found() -> None:
    """fx = 384 puts the corner 1.04 focal lengths out, beyond k1 = -0.3's peak of 0.703, where the polynomial meets
    it again only on its folded-back branch (r about -2.2): an exact solution, but not a ray of the image."""
    cam = Camera(fx=384.0, fy=384.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.3})
    assert distortion_fold(cam) is not None


def test_transforms_json_with_a_folding_distortion_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "transforms.json"
    d = {
        "camera_model": "OPENCV",
        "fl_x": 512.0,
        "fl_y": 512.0,
        "cx": 320.0,
        "cy": 240.0,
        "w": 640,
        "h": 480,
        "k1": -0.3,
    }
    path.write_text(json.dumps(d))
    with pytest.raises(
        SceneError,
        match=r"top level: the lens distortion \(k1 -0.3\) cannot be inverted .* "
        r"undistort the images",
    ):
        camera_from_dict(d, path, "top level")
    assert camera_from_dict(d | {"k2": 0.05}, path, "top level").distortion == {"k1": -0.3, "k2": 0.05}


def test_the_jacobian_is_the_derivative_of_the_distortion() -> None:
    """``_jacobian`` (used by Newton's steps and by ``distortion_fold``'s orientation test) against central
    differences of ``distort_normalized`` with every coefficient non-zero: their error is ~h^2 = 1e-12."""
    cam = Camera(fx=1.0, fy=1.0, cx=0.0, cy=0.0, width=2, height=2,
                 distortion={"k1": -0.21, "k2": 0.07, "k3": -0.013, "k4": 0.004, "p1": 0.011, "p2": -0.017})
    x, y = np.array([0.31, -0.52, 0.77]), np.array([-0.44, 0.09, 0.63])
    h = 1e-6
    dx = [(a - b) / (2 * h) for a, b in zip(camera_module.distort_normalized(cam, x + h, y),
                                            camera_module.distort_normalized(cam, x - h, y), strict=True)]
    dy = [(a - b) / (2 * h) for a, b in zip(camera_module.distort_normalized(cam, x, y + h),
                                            camera_module.distort_normalized(cam, x, y - h), strict=True)]
    j11, j12, j22 = camera_module._jacobian(cam, x, y)
    np.testing.assert_allclose(j11, dx[0], atol=1e-8)
    np.testing.assert_allclose(j12, dy[0], atol=1e-8)  # d xd / dy
    np.testing.assert_allclose(j12, dx[1], atol=1e-8)  # d yd / dx: the Jacobian is symmetric
    np.testing.assert_allclose(j22, dy[1], atol=1e-8)


def test_newton_converges_quadratically_from_the_distorted_point(monkeypatch: pytest.MonkeyPatch) -> None:
    """Started at the distorted corners of the 640x480 image (fx = 512, k1 = -0.3, k2 = 0.05, p1 = -p2 = 0.01),
    Newton's worst residual falls as its square a step once near (2e-3, 4e-5, 3e-8, 2e-14 after steps 4 to 7):
    eight steps are ample for 1e-13. A wrong Jacobian (a sign of its off-diagonal term, a coefficient) still
    converges in the 60 allowed, linearly (1e-4 after 13 steps): this is where it shows."""
    monkeypatch.setattr(camera_module, "NEWTON_STEPS", 8)
    cam = Camera(fx=512.0, fy=512.0, cx=320.0, cy=240.0, width=640, height=480,
                 distortion={"k1": -0.3, "k2": 0.05, "p1": 0.01, "p2": -0.01})
    xd, yd = np.array([-319.5, 319.5, -319.5, 319.5]) / 512, np.array([-239.5, -239.5, 239.5, 239.5]) / 512
    x, y = camera_module._newton_undistort(cam, xd, yd)
    rx, ry = camera_module.distort_normalized(cam, x, y)
    assert np.hypot(rx - xd, ry - yd).max() < 1e-13


def test_a_fold_between_the_grid_pixels_is_found() -> None:
    """k1 = -0.6, k2 = 0.16: the radial map's slope 1 - 1.8 r^2 + 0.8 r^4 is 0 at r^2 = 1 and 1.25, so it folds back
    between r = 1 (r_d = 0.56) and 1.118 (r_d = 0.559): a band of r_d a thousandth wide, which no pixel of the
    17 x 17 grid falls in at fx = 600 (every grid pixel has a ray where the map keeps its orientation). The image
    reaches r_d = 399.3 / 600 = 0.666, beyond the fold: the disk of rays finds it, starting at r = 1."""
    cam = Camera(fx=600.0, fy=600.0, cx=320.0, cy=240.0, width=640, height=480, distortion={"k1": -0.6, "k2": 0.16})
    problem = distortion_fold(cam) or ""
    assert problem.startswith("the distortion folds "), problem
    radius = float(problem.split()[3])
    assert 0.999 <= radius <= 1.012, problem  # the first of 129 radii (steps of 1.47 / 128) at or beyond 1


def test_the_fold_check_of_one_camera_is_not_reused_for_another_principal_point(tmp_path: Path) -> None:
    """The fold check is cached per camera: k1 = -0.3 at fx = 640 is fold-free with the principal point in the
    middle (the corner 0.625 focal lengths out, short of the 0.703 peak) and folds with it at the bottom edge
    (the top corners (-0.5, -0.75) focal lengths out: 0.90)."""
    path = tmp_path / "transforms.json"
    d = {"camera_model": "OPENCV", "fl_x": 640.0, "fl_y": 640.0, "cx": 320.0, "cy": 240.0, "w": 640, "h": 480,
         "k1": -0.3}
    assert camera_from_dict(d, path, "top level").distortion == {"k1": -0.3}
    with pytest.raises(SceneError, match="cannot be inverted"):
        camera_from_dict(d | {"cy": 480.0}, path, "top level")
    with pytest.raises(SceneError, match="cannot be inverted"):
        camera_from_dict(d | {"cx": 640.0, "cy": 240.0}, path, "top level")
