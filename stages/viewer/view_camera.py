"""The browser's camera <-> the dataset's camera: poses, intrinsics, frustums and the scene's up direction.

viser reports a client's camera as a camera-to-world rotation (``wxyz``) and position in OpenCV camera
axes (x right, y down, z forward) with a vertical field of view; the run API takes 4x4 camera-to-world
matrices in OpenGL axes (x right, y up, z back; docs/model.md). The viewer keeps viser's world = the
dataset's world (no rescaling), so a training pose shown as a frustum and the client's camera placed on
it give the training frame's render.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from stages.scene import Camera, opengl_to_opencv


def rotation_to_wxyz(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(w, x, y, z)`` of a 3x3 rotation matrix (w >= 0)."""
    m = np.asarray(rotation, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    # branch on the largest diagonal term so the square root never sees a number near 0
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    out = np.asarray(q, dtype=np.float64)
    out /= np.linalg.norm(out)
    return out if out[0] >= 0 else -out


def wxyz_to_rotation(wxyz: Sequence[float] | np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a quaternion ``(w, x, y, z)`` (normalised first)."""
    w, x, y, z = np.asarray(wxyz, dtype=np.float64) / np.linalg.norm(np.asarray(wxyz, dtype=np.float64))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def viser_pose(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(wxyz, position)`` of an OpenGL camera-to-world as viser places cameras and frustums (OpenCV axes)."""
    cv = opengl_to_opencv(np.asarray(c2w, dtype=np.float64))
    return rotation_to_wxyz(cv[:3, :3]), cv[:3, 3].copy()


def vertical_fov(camera: Camera) -> float:
    """Vertical field of view (radians) of a pinhole camera, as viser's ``fov`` is given."""
    return 2.0 * math.atan(camera.height / (2.0 * camera.fy))


@dataclass(frozen=True)
class ViewPose:
    """What a client looks at: an OpenGL camera-to-world in dataset coordinates, a vertical fov and an aspect."""

    c2w: np.ndarray
    fov_y: float
    aspect: float

    @classmethod
    def from_viser(cls, wxyz: Sequence[float] | np.ndarray, position: Sequence[float] | np.ndarray,
                   fov_y: float, aspect: float) -> ViewPose:
        c2w = np.eye(4)
        c2w[:3, :3] = wxyz_to_rotation(wxyz)
        c2w[:3, 3] = np.asarray(position, dtype=np.float64)
        return cls(c2w=opengl_to_opencv(c2w), fov_y=float(fov_y), aspect=float(aspect))

    def camera(self, width: int, height: int) -> Camera:
        """A distortion-free pinhole camera of ``width`` x ``height`` pixels with this view's vertical fov.

        Square pixels: the horizontal fov follows from the image's aspect, which the renderer picks equal to
        the client's canvas (viser stretches the background image over the canvas).
        """
        fy = height / (2.0 * math.tan(self.fov_y / 2.0))
        return Camera(fx=fy, fy=fy, cx=width / 2.0, cy=height / 2.0, width=int(width), height=int(height))

    def same_view(self, other: ViewPose | None, tol: float = 1e-9) -> bool:
        """Whether ``other`` shows the same image (pose, fov and aspect equal up to ``tol``)."""
        return (other is not None and abs(self.fov_y - other.fov_y) <= tol and abs(self.aspect - other.aspect) <= tol
                and bool(np.allclose(self.c2w, other.c2w, rtol=0.0, atol=tol)))


def scene_up(c2ws: Sequence[np.ndarray]) -> np.ndarray:
    """The world's up direction as the training cameras see it, whatever convention the poses use.

    A handheld or tripod capture keeps the camera's x axis (image right) level, so up is the direction
    perpendicular to every camera's right axis: the least eigenvector of the right axes' scatter. The mean of
    the cameras' up axes only picks its sign: alone it is biased by pitch (cameras looking down at a table tilt
    their up axes towards it) wherever the orbit is not a full circle. When the right axes are all parallel
    (a straight dolly) the scatter has no least direction and the mean up axis, made perpendicular to them,
    is used; +z when the cameras say nothing (z-up is the capture generator's convention).
    """
    if not len(c2ws):
        return np.array([0.0, 0.0, 1.0])
    poses = np.stack([np.asarray(c, dtype=np.float64)[:3, :3] for c in c2ws])
    rights, ups = poses[:, :, 0], poses[:, :, 1]
    mean_up = ups.mean(axis=0)
    values, vectors = np.linalg.eigh(rights.T @ rights / len(rights))  # ascending eigenvalues
    if values[1] > 1e-3:  # the right axes span a plane: its normal is up
        up = vectors[:, 0]
    else:
        right = vectors[:, 2]
        up = mean_up - float(mean_up @ right) * right
    norm = float(np.linalg.norm(up))
    if norm < 1e-6:
        return np.array([0.0, 0.0, 1.0])
    up = up / norm
    return up if float(up @ mean_up) >= 0 else -up


def frustum_scale(centres: np.ndarray) -> float:
    """Size (world units) of the training-camera frustums: about the spacing of neighbouring cameras.

    Twice the median distance to the nearest other camera, kept within 1 % .. 5 % of the cameras' spread,
    so that a video's frustums do not overlap into one blob and a sparse capture's are still visible.
    """
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    spread = float(np.linalg.norm(centres.max(axis=0) - centres.min(axis=0))) if len(centres) else 0.0
    if len(centres) < 2 or spread <= 0:
        return 0.1
    centres = centres[np.linspace(0, len(centres) - 1, min(len(centres), 500)).astype(int)]  # O(n^2) below
    dist = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=-1)
    np.fill_diagonal(dist, np.inf)
    nearest = float(np.median(dist.min(axis=1)))
    return float(np.clip(2.0 * nearest, 0.01 * spread, 0.05 * spread))


def look_at_point(c2w: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The point on the camera's viewing axis nearest to ``target`` (at least a small step in front).

    viser orbits around a look-at point; putting it on the viewing axis keeps the first frame identical to the
    training view while orbiting happens around the middle of the scene.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    forward = -c2w[:3, 2]  # OpenGL cameras look along -z
    along = float(np.dot(np.asarray(target, dtype=np.float64) - c2w[:3, 3], forward))
    return c2w[:3, 3] + forward * max(along, 1e-3)
