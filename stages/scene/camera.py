"""Pinhole cameras with OpenCV distortion, and ray generation in OpenGL axes.

Conventions (those of nerfstudio's ``transforms.json``): a pose is a 4x4
camera-to-world matrix whose camera looks down its -z axis with +y up and +x
right. Pixel (u, v) has its centre at (u + 0.5, v + 0.5).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


@dataclass(frozen=True)
class Camera:
    """Intrinsics of one camera."""

    fx: float
    """Focal length along x, in pixels."""
    fy: float
    """Focal length along y, in pixels."""
    cx: float
    """Principal point x, in pixels (0 = left edge of the image)."""
    cy: float
    """Principal point y, in pixels (0 = top edge of the image)."""
    width: int
    """Image width, in pixels."""
    height: int
    """Image height, in pixels."""
    distortion: dict[str, float] = field(default_factory=dict)
    """OpenCV radial/tangential coefficients k1..k4, p1, p2 (missing = 0)."""

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    @property
    def has_distortion(self) -> bool:
        return any(abs(self.distortion.get(k, 0.0)) > 0 for k in DISTORTION_KEYS)

    def scaled(self, factor: float) -> Camera:
        """The same camera for images resized by ``factor`` (0.5 = half size)."""
        return replace(
            self,
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=self.cx * factor,
            cy=self.cy * factor,
            width=round(self.width * factor),
            height=round(self.height * factor),
        )

    @classmethod
    def from_fov(cls, fov_x: float, width: int, height: int) -> Camera:
        """Blender-style camera: horizontal field of view in radians, square pixels."""
        f = 0.5 * width / np.tan(0.5 * fov_x)
        return cls(fx=f, fy=f, cx=width / 2.0, cy=height / 2.0, width=width, height=height)


def undistort_normalized(camera: Camera, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert OpenCV radial-tangential distortion on normalised image coordinates.

    Fixed-point iteration as in OpenCV's ``undistortPoints``; 10 iterations are
    ample for the mild distortion of phone cameras.
    """
    d = camera.distortion
    k1, k2, k3, k4 = (d.get(k, 0.0) for k in ("k1", "k2", "k3", "k4"))
    p1, p2 = d.get("p1", 0.0), d.get("p2", 0.0)
    x, y = xd.copy(), yd.copy()
    for _ in range(10):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3 + k4 * r2**4
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    return x, y


def pixel_directions(camera: Camera, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unnormalised ray directions in OpenGL camera axes for pixel indices (u, v).

    Returns ``[..., 3]`` with z = -1.
    """
    x = (np.asarray(u, dtype=np.float64) + 0.5 - camera.cx) / camera.fx
    y = (np.asarray(v, dtype=np.float64) + 0.5 - camera.cy) / camera.fy
    if camera.has_distortion:
        x, y = undistort_normalized(camera, x, y)
    # OpenCV camera (x right, y down, z forward) -> OpenGL (x right, y up, z back)
    return np.stack([x, -y, -np.ones_like(x)], axis=-1)


def generate_rays(
    camera: Camera, c2w: np.ndarray, u: np.ndarray | None = None, v: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """World-space ray origins and unit directions.

    Without ``u``/``v`` every pixel is used and the result is ``[H, W, 3]``;
    otherwise the shape follows ``u``.
    """
    if u is None or v is None:
        v, u = np.meshgrid(np.arange(camera.height), np.arange(camera.width), indexing="ij")
    dirs_cam = pixel_directions(camera, u, v)
    c2w = np.asarray(c2w, dtype=np.float64)
    dirs = dirs_cam @ c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    origins = np.broadcast_to(c2w[:3, 3], dirs.shape).copy()
    return origins, dirs


def project_points(camera: Camera, c2w: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points to pixel coordinates (no distortion); returns ``(uv, depth)``.

    ``depth`` is the distance along the viewing axis (positive in front).
    """
    w2c = np.linalg.inv(np.asarray(c2w, dtype=np.float64))
    p = np.asarray(points, dtype=np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -p[..., 2]
    u = camera.fx * p[..., 0] / depth + camera.cx
    v = -camera.fy * p[..., 1] / depth + camera.cy
    return np.stack([u, v], axis=-1), depth


def opengl_to_opencv(c2w: np.ndarray) -> np.ndarray:
    """Flip the y and z camera axes: OpenGL camera-to-world <-> OpenCV camera-to-world."""
    out = np.array(c2w, dtype=np.float64, copy=True)
    out[:3, 1:3] *= -1
    return out


opencv_to_opengl = opengl_to_opencv  # the flip is its own inverse


def look_at(eye: np.ndarray, target: np.ndarray, up: tuple[float, float, float] = (0.0, 0.0, 1.0)) -> np.ndarray:
    """OpenGL camera-to-world matrix at ``eye`` looking at ``target`` (camera -z towards it, +y roughly ``up``)."""
    eye = np.asarray(eye, dtype=np.float64)
    back = eye - np.asarray(target, dtype=np.float64)
    back /= np.linalg.norm(back)
    right = np.cross(np.asarray(up, dtype=np.float64), back)
    right /= np.linalg.norm(right)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, np.cross(back, right), back, eye
    return c2w
