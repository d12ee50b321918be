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


def _coefficients(camera: Camera) -> tuple[float, float, float, float, float, float]:
    d = camera.distortion
    return tuple(float(d.get(k, 0.0)) for k in ("k1", "k2", "k3", "k4", "p1", "p2"))  # type: ignore[return-value]


def distort_normalized(camera: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply OpenCV radial-tangential distortion to normalised image coordinates (what ``cv2.projectPoints`` does
    between the camera axes and the intrinsics; k4 is nerfstudio's r^8 term)."""
    k1, k2, k3, k4, p1, p2 = _coefficients(camera)
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * (k3 + r2 * k4)))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


KEEP_TOLERANCE = 1e-9
"""Normalised residual under which the fixed-point inverse is kept: 1e-6 px at a focal length of 1000 px, below
the float32 of the rays (6e-8 of their length); every pixel of a phone camera's gets there in 10 iterations."""
NEWTON_TOLERANCE = 1e-13
NEWTON_STEPS = 60
HALVINGS = 40


def _jacobian(camera: Camera, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(d xd/dx, d xd/dy = d yd/dx, d yd/dy) of ``distort_normalized``: the Jacobian is symmetric."""
    k1, k2, k3, k4, p1, p2 = _coefficients(camera)
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3 + k4 * r2**4
    slope = k1 + 2 * k2 * r2 + 3 * k3 * r2**2 + 4 * k4 * r2**3  # d radial / d r2
    return (radial + 2 * x * x * slope + 2 * p1 * y + 6 * p2 * x,
            2 * x * y * slope + 2 * p1 * x + 2 * p2 * y,
            radial + 2 * y * y * slope + 6 * p1 * y + 2 * p2 * x)


def _newton_undistort(camera: Camera, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Newton's method on the distortion's 2x2 Jacobian, started at the distorted point, each step halved until it
    lowers the residual: the fixed-point iteration's contraction factor ``2 |k1| r^2 / (1 + k1 r^2)`` nears 1 at
    strong barrel distortion, where it stalls or oscillates; a plain Newton step leaps off where the radial map is
    nearly flat (k1 = -0.48, k2 = 0.105), the halving keeps it on the branch it started on. Only the points not
    yet solved are iterated."""
    x, y = xd.astype(np.float64, copy=True), yd.astype(np.float64, copy=True)
    fx, fy = distort_normalized(camera, x, y)
    fx, fy = fx - xd, fy - yd
    active = np.flatnonzero(~(np.hypot(fx, fy) <= NEWTON_TOLERANCE))
    for _ in range(NEWTON_STEPS):
        if active.size == 0:
            break
        ax, ay, afx, afy, axd, ayd = x[active], y[active], fx[active], fy[active], xd[active], yd[active]
        norm = np.hypot(afx, afy)
        j11, j12, j22 = _jacobian(camera, ax, ay)
        det = j11 * j22 - j12 * j12
        ok = np.abs(det) > 1e-15  # a fold of the model: no step (distortion_fold names such cameras)
        safe = np.where(ok, det, 1.0)
        sx = np.where(ok, (j22 * afx - j12 * afy) / safe, 0.0)
        sy = np.where(ok, (j11 * afy - j12 * afx) / safe, 0.0)
        t = np.ones_like(ax)
        nx, ny = distort_normalized(camera, ax - sx, ay - sy)
        nx, ny = nx - axd, ny - ayd
        for _ in range(HALVINGS):  # (nx, ny) is always the residual at step t
            worse = ~(np.hypot(nx, ny) < norm)
            if not worse.any():
                break
            t = np.where(worse, 0.5 * t, t)
            nx, ny = distort_normalized(camera, ax - t * sx, ay - t * sy)
            nx, ny = nx - axd, ny - ayd
        better = np.hypot(nx, ny) < norm
        x[active] = np.where(better, ax - t * sx, ax)
        y[active] = np.where(better, ay - t * sy, ay)
        fx[active], fy[active] = np.where(better, nx, afx), np.where(better, ny, afy)
        # done: solved, or no step lowers the residual any more (a fold, or the last bits of float64)
        active = active[better & ~(np.hypot(nx, ny) <= NEWTON_TOLERANCE)]
    return x, y


def undistort_normalized(camera: Camera, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Invert OpenCV radial-tangential distortion on normalised image coordinates.

    Fixed-point iteration as in OpenCV's ``undistortPoints`` (10 iterations: a phone camera's pixels converge to
    float32 precision), then Newton's method for the points it left off by more than ``KEEP_TOLERANCE``: at
    k1 = -0.3, k2 = 0.05 the fixed point ends 0.2 px off at a 640x480 image's corner (fx = 512), Newton 3e-14 px
    (docs/data-contract.md, "Lens distortion"). A point beyond the model's fold (no ray distorts onto it) keeps
    the best try; ``distortion_fold`` finds such cameras.
    """
    k1, k2, k3, k4, p1, p2 = _coefficients(camera)
    x, y = xd.copy(), yd.copy()
    for _ in range(10):
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3 + k4 * r2**4
        dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        x = (xd - dx) / radial
        y = (yd - dy) / radial
    rx, ry = distort_normalized(camera, x, y)
    off = ~(np.hypot(rx - xd, ry - yd) <= KEEP_TOLERANCE)  # NaN (a diverged iteration) counts as off
    if off.any():
        x, y = np.array(x, dtype=np.float64), np.array(y, dtype=np.float64)
        x[off], y[off] = _newton_undistort(camera, np.asarray(xd)[off], np.asarray(yd)[off])
    return x, y


FOLD_GRID = 17
"""Pixels per image side (corners and edges included) at which ``distortion_fold`` checks the inverse."""


def distortion_fold(camera: Camera, tolerance_px: float = 0.01) -> str | None:
    """Why some pixel of the image has no ray, or more than one (None when every pixel has one).

    Strong barrel coefficients without the higher terms that balance them make the polynomial
    ``r (1 + k1 r^2 + k2 r^4 + ..)`` turn back (its slope ``1 + 3 k1 r^2 + 5 k2 r^4 + ..`` reaches 0), and with the
    tangential terms the map can fold where that slope is nearly 0: the pixels beyond are the image of no ray, or
    of a second, folded-back one. Checked on a ``FOLD_GRID`` x ``FOLD_GRID`` grid of pixel centres over the image:
    each must be reached within ``tolerance_px`` by a ray where the map keeps its orientation (positive Jacobian
    determinant), and so must every ray out to the farthest of them.
    """
    if not camera.has_distortion:
        return None
    w, h = camera.width, camera.height
    v, u = np.meshgrid(np.linspace(0.5, h - 0.5, FOLD_GRID), np.linspace(0.5, w - 0.5, FOLD_GRID), indexing="ij")
    u, v = u.ravel(), v.ravel()
    xd, yd = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy
    x, y = undistort_normalized(camera, xd, yd)
    rx, ry = distort_normalized(camera, x, y)
    miss = np.hypot((rx - xd) * camera.fx, (ry - yd) * camera.fy)
    j11, j12, j22 = _jacobian(camera, x, y)
    miss = np.where(np.isfinite(miss) & (j11 * j22 - j12 * j12 > 0), miss, np.inf)
    worst = int(np.argmax(miss))
    if miss[worst] > tolerance_px:
        how = "no ray reaches it" if np.isinf(miss[worst]) else f"the nearest ray lands {miss[worst]:.3g} px away"
        return f"pixel ({u[worst]:g}, {v[worst]:g}) is the image of no ray ({how}): the distortion folds in the image"
    # the map must keep its orientation over the whole disk of rays out to the farthest pixel's, not only at the
    # grid's rays: a fold between grid pixels (a few pixels wide at k1 = -0.48, k2 = 0.105) slips through them
    radius = np.linspace(0.0, float(np.sqrt(np.max(x * x + y * y))), 129)[:, None]
    angle = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)[None, :]
    j11, j12, j22 = _jacobian(camera, radius * np.cos(angle), radius * np.sin(angle))
    folded = (j11 * j22 - j12 * j12 <= 0).any(axis=1)
    if folded.any():
        return (f"the distortion folds {radius[np.argmax(folded), 0]:.3g} focal lengths from the principal point, "
                f"inside the {radius[-1, 0]:.3g} the image reaches: pixels there are the image of two rays or none")
    return None


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
    """Project world points to pixel coordinates through the camera's distortion (as ``cv2.projectPoints``);
    returns ``(uv, depth)``.

    ``depth`` is the distance along the viewing axis (positive in front).
    """
    w2c = np.linalg.inv(np.asarray(c2w, dtype=np.float64))
    p = np.asarray(points, dtype=np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -p[..., 2]
    if not camera.has_distortion:  # the pinhole arithmetic as it always was (the same bits)
        u = camera.fx * p[..., 0] / depth + camera.cx
        v = -camera.fy * p[..., 1] / depth + camera.cy
        return np.stack([u, v], axis=-1), depth
    x, y = distort_normalized(camera, p[..., 0] / depth, -p[..., 1] / depth)  # OpenCV axes: y down
    return np.stack([camera.fx * x + camera.cx, camera.fy * y + camera.cy], axis=-1), depth


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
