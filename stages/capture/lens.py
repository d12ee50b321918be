"""The capture camera's lens: a pinhole of the spec's field of view with OpenCV radial-tangential distortion, and
the check that its distortion can be rendered (docs/captures.md, "Phone camera effects").

Rays leave each pixel in the direction ``stages.scene.camera.undistort_normalized`` finds for it (OpenCV's
fixed-point iteration, 10 steps); the truth camera in truth/transforms.json carries the same coefficients, so
every reader of the truth renders through the same lens.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from stages.scene import Camera
from stages.scene.camera import undistort_normalized

from .spec import VideoSpec

ROUND_TRIP_PX = 0.01
"""A pixel's undistorted ray, distorted again by OpenCV, must land this near (pixels) on the pixel it left."""
GRID = 33
"""Pixels checked per image side (plus every pixel of the border, where distortion is strongest)."""


def lens_camera(video: VideoSpec) -> Camera:
    """The capture camera: ``fov_deg`` is the undistorted pinhole's horizontal field of view (a barrel lens, k1 < 0,
    then sees more than it at the edges); coefficients left at 0 are not written."""
    camera = Camera.from_fov(np.deg2rad(video.fov_deg), video.width, video.height)
    coefficients = {k: float(v) for k, v in dataclasses.asdict(video.distortion).items() if v != 0.0}
    return dataclasses.replace(camera, distortion=coefficients) if coefficients else camera


def distort_normalized(camera: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's own forward model (``cv2.projectPoints``) on normalised undistorted coordinates."""
    d = camera.distortion
    coeffs = np.array([d.get(k, 0.0) for k in ("k1", "k2", "p1", "p2")], dtype=np.float64)
    points = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1)
    out, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), np.eye(3), coeffs)
    return out[:, 0, 0].reshape(x.shape), out[:, 0, 1].reshape(x.shape)


def _check_pixels(camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centres (u, v) of a grid over the image and of its whole border."""
    w, h = camera.width, camera.height
    gu, gv = np.meshgrid(np.linspace(0, w - 1, GRID), np.linspace(0, h - 1, GRID))
    border_u = np.r_[np.arange(w), np.arange(w), np.zeros(h), np.full(h, w - 1)]
    border_v = np.r_[np.zeros(w), np.full(w, h - 1), np.arange(h), np.arange(h)]
    return np.r_[gu.ravel(), border_u] + 0.5, np.r_[gv.ravel(), border_v] + 0.5


def lens_problem(camera: Camera) -> str | None:
    """Why ``camera``'s distortion cannot be rendered over its image, or None.

    Measured on the image itself (its field of view matters as much as the coefficients): each pixel checked must
    find its ray, i.e. OpenCV's forward model must take the ray that ``undistort_normalized`` (10 fixed-point steps,
    what every stage's ray generation uses) gives a pixel back onto that pixel. The steps stop converging well
    before a lens would fold the image over itself (no set of 3,000 random k1, k2, p1, p2 converged past a fold
    when this was written), so this one test also keeps the image one to one. At the demo's 65-degree view it
    accepts k1 in [-0.20, 0.67] (k2 = 0) and k2 in [-0.17, 0.51] (k1 = 0)."""
    if not camera.has_distortion:
        return None
    u, v = _check_pixels(camera)
    xd, yd = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy
    with np.errstate(all="ignore"):  # a diverging iteration overflows: that is the answer
        x, y = undistort_normalized(camera, xd, yd)
        rx, ry = distort_normalized(camera, np.nan_to_num(x), np.nan_to_num(y))
        miss = np.hypot((rx - xd) * camera.fx, (ry - yd) * camera.fy)
    miss = np.where(np.isfinite(x) & np.isfinite(y) & np.isfinite(miss), miss, np.inf)
    worst = int(np.argmax(miss))
    if miss[worst] > ROUND_TRIP_PX:
        return (
            f"pixel ({u[worst]:.1f}, {v[worst]:.1f}) finds no ray (the ray OpenCV's undistortion gives it lands "
            f"{miss[worst]:.3g} px off it through the lens): the distortion is too strong for this "
            f"{camera.width}x{camera.height} image and its field of view"
        )
    return None
