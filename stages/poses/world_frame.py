"""A gravity- and wall-aligned world frame for a reconstruction (docs/poses.md, "World frame").

COLMAP leaves the world where its first image pair put it, so a room's floor and walls lie at arbitrary
angles to the axes. Every field of the model stage factorises space into axis-aligned planes, and the
scene box is axis-aligned: a tilted room costs plane capacity and box volume (measured on the demo capture,
docs/poses.md). Indoor scenes are close to a Manhattan world, so the frame is turned until

- z is "up": the mean camera up vector, refined by the point normals close to it (floor, table tops,
  ceiling), and
- x and y follow the walls: the angle of the near-horizontal point normals, taken modulo 90 degrees (the
  circular mean of 4 theta), of the four equivalent choices the one closest to the cameras' mean right
  vector.

The origin moves to the centre of the box around the points (outliers removed) and camera centres. Scale is
left as it is. Without a clear wall direction (``yaw_strength`` below ``MIN_YAW_STRENGTH``) x stays the
cameras' mean right vector, made horizontal.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import open3d as o3d
import pycolmap

from .model_export import inlier_points, point_cloud, registered_poses

UP_CONE_DEG = 30.0
"""Point normals within this angle of the cameras' up vector refine it (floor, table tops, ceiling)."""
WALL_CONE_DEG = 30.0
"""Point normals within this angle of the horizontal plane give the wall directions."""
MIN_UP_SHARE = 0.05
"""Fewer refining normals than this share of the points (or 10) leave the cameras' up vector as it is."""
MIN_YAW_STRENGTH = 0.1
"""Resultant length of the 4-theta circular mean below which the walls are not trusted (random normals give
about 1 / sqrt(n), 0.03 for a thousand points; the synthetic rooms give 0.3 to 0.5)."""
NORMAL_NEIGHBOURS = 20
"""Neighbours of a point whose plane gives its normal."""


@dataclass
class WorldFrame:
    """The rigid motion ``x_new = rotation @ x_old + translation`` and how it was found."""

    rotation: np.ndarray
    translation: np.ndarray
    up_source: str
    """"point normals" or "camera up vectors"."""
    yaw_source: str
    """"wall normals" or "camera right vectors"."""
    up_tilt_deg: float
    """Angle between the cameras' mean up vector and the chosen up (how much the normals moved it)."""
    yaw_strength: float
    """Resultant length of the wall normals' 4-theta circular mean (1 = every normal on one of four axes)."""
    n_points: int

    @property
    def matrix(self) -> np.ndarray:
        """3x4 ``[R | t]`` (COLMAP's Sim3d with scale 1)."""
        return np.concatenate([self.rotation, self.translation[:, None]], axis=1)

    def as_dict(self) -> dict[str, Any]:
        return {"new_from_old": self.matrix.tolist(), "up_source": self.up_source, "yaw_source": self.yaw_source,
                "up_tilt_deg": self.up_tilt_deg, "yaw_strength": self.yaw_strength, "n_points": self.n_points,
                "rule": "z up (camera up, refined by point normals), x and y along the walls (point normals "
                        "modulo 90 degrees), origin at the box centre; docs/poses.md"}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / max(float(np.linalg.norm(v)), 1e-12)


def point_normals(points: np.ndarray, neighbours: int = NORMAL_NEIGHBOURS) -> np.ndarray:
    """Unoriented unit normals [N, 3] from the plane through each point's neighbours (open3d)."""
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=neighbours))
    return np.asarray(cloud.normals).copy()


def estimate_world_frame(points: np.ndarray, camera_c2w: np.ndarray) -> WorldFrame:
    """The frame of the module docstring from points [N, 3] (outliers removed) and OpenGL camera-to-world [M, 4, 4].

    Cameras alone (no points) give z = their mean up vector and x = their mean right vector.
    """
    c2w = np.asarray(camera_c2w, dtype=np.float64).reshape(-1, 4, 4)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    camera_up = _unit(c2w[:, :3, 1].sum(0))  # OpenGL cameras: +y is up in the image
    normals = point_normals(points) if len(points) > NORMAL_NEIGHBOURS else np.zeros((0, 3))

    up, up_source = camera_up, "camera up vectors"
    near_up = normals[np.abs(normals @ camera_up) > np.cos(np.radians(UP_CONE_DEG))]
    if len(near_up) >= max(10, MIN_UP_SHARE * len(points)):
        _, vectors = np.linalg.eigh(near_up.T @ near_up)  # the dominant axis of the normals, sign free
        up = vectors[:, -1] * np.sign(vectors[:, -1] @ camera_up)
        up_source = "point normals"

    # a horizontal basis (e1 from the cameras' mean right vector) in which the wall angles are measured
    e1 = c2w[:, :3, 0].sum(0)
    e1 = e1 - (e1 @ up) * up
    if np.linalg.norm(e1) < 1e-6:  # cameras whose right vectors cancel: any horizontal direction will do
        e1 = np.cross(up, np.eye(3)[int(np.argmin(np.abs(up)))])
    e1 = _unit(e1)
    e2 = np.cross(up, e1)
    walls = normals[np.abs(normals @ up) < np.sin(np.radians(WALL_CONE_DEG))]
    strength, yaw, yaw_source = 0.0, 0.0, "camera right vectors"
    if len(walls):
        theta = np.arctan2(walls @ e2, walls @ e1)
        mean = np.exp(4j * theta).mean()
        strength = float(abs(mean))
        if strength >= MIN_YAW_STRENGTH:
            yaw, yaw_source = float(np.angle(mean)) / 4.0, "wall normals"  # in [-45, 45] degrees of e1
    x = np.cos(yaw) * e1 + np.sin(yaw) * e2
    rotation = np.stack([x, np.cross(up, x), up])
    if up_source == "point normals" and yaw_source == "wall normals":
        rotation = refine_manhattan(rotation, normals)
        up = rotation[2]

    turned = np.concatenate([points, c2w[:, :3, 3]]) @ rotation.T
    centre = 0.5 * (turned.min(0) + turned.max(0))
    tilt = float(np.degrees(np.arccos(np.clip(up @ camera_up, -1.0, 1.0))))
    return WorldFrame(rotation=rotation, translation=-centre, up_source=up_source, yaw_source=yaw_source,
                      up_tilt_deg=tilt, yaw_strength=strength, n_points=len(points))


def refine_manhattan(rotation: np.ndarray, normals: np.ndarray, cones_deg: tuple[float, ...] = (20.0, 10.0, 10.0)
                     ) -> np.ndarray:
    """Turn the three axes together onto the normals around each of them (rows of ``rotation`` are the axes).

    Each round takes, per axis, the dominant direction of the normals within the cone around it, and the
    rotation nearest to those directions weighted by their normal counts (orthogonal Procrustes). The
    current axes keep a small weight, so an axis without normals (no ceiling, one wall) follows the others.
    """
    for cone in cones_deg:
        target = np.zeros((3, 3))
        for i, axis in enumerate(rotation):
            near = normals[np.abs(normals @ axis) > np.cos(np.radians(cone))]
            direction = axis
            if len(near) >= 3:
                _, vectors = np.linalg.eigh(near.T @ near)
                direction = vectors[:, -1] * np.sign(vectors[:, -1] @ axis)
            target += np.outer(np.eye(3)[i], direction) * len(near) + np.outer(np.eye(3)[i], axis) * 0.01 * len(normals)
        u, _, vt = np.linalg.svd(target)
        rotation = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt
    return rotation


def orient_reconstruction(reconstruction: pycolmap.Reconstruction) -> WorldFrame:
    """Move ``reconstruction`` (cameras and points, in place) into the frame of ``estimate_world_frame``.

    The normals come from the points left by the scene box's outlier filter, so stray triangulations
    neither vote for a wall nor stretch the box whose centre becomes the origin.
    """
    poses = registered_poses(reconstruction)
    c2w = np.stack(list(poses.values())) if poses else np.zeros((0, 4, 4))
    points = np.asarray(inlier_points(point_cloud(reconstruction)).points)
    frame = estimate_world_frame(points, c2w)
    reconstruction.transform(pycolmap.Sim3d(frame.matrix))
    return frame
