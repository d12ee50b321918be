"""A second, independent estimate of "up" that checks the world frame (docs/poses.md, "World frame").

``world_frame.py`` takes up from the cameras' mean up vector refined by the point normals near it; normals come from
plane fits over 20 neighbours, which a sparse, noisy cloud (a low-texture room: a few hundred points) makes noisy,
and the result then lies several degrees from upright with nothing to show it. The check here uses no normals and no
camera: the largest plane of the points within ``MAX_TILT_DEG`` of the world's z (the floor, or table tops), found by
RANSAC on point triples and refitted to its inliers. A plane whose normal disagrees with z by more than
``WARN_DEG`` gives a warning; the world frame itself is never changed by it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pycolmap

from .model_export import inlier_points, point_cloud

MAX_TILT_DEG = 20.0
"""Only planes within this angle of the world's z are candidates for the floor or a table top."""
INLIER_FRACTION = 0.005
"""A point lies on a plane when within this fraction of the cloud's size (its 5-95 % percentile box's longest
side) of it."""
MIN_INLIERS = 30
"""A plane with fewer points than this says nothing (and the check is left out)."""
HYPOTHESES = 3000
"""Random point triples tried (seeded: the same points give the same plane)."""
WARN_DEG = 2.0
"""Warn when the plane's normal lies farther than this from the world's z (chosen from measurements:
docs/poses.md, "World frame")."""


@dataclass
class UpCheck:
    plane_tilt_deg: float | None
    """Angle between the largest near-horizontal plane's normal and the world's z; None when no plane was found."""
    plane_points: int
    """Points on that plane."""
    n_points: int

    @property
    def disagrees(self) -> bool:
        return self.plane_tilt_deg is not None and self.plane_tilt_deg > WARN_DEG

    def as_dict(self) -> dict[str, Any]:
        return {
            "plane_tilt_deg": self.plane_tilt_deg,
            "plane_points": self.plane_points,
            "n_points": self.n_points,
            "warn_above_deg": WARN_DEG,
            "rule": "largest plane of the points within 20 degrees of z (RANSAC, refitted), its normal against "
            "z; docs/poses.md",
        }

    def warning(self) -> str | None:
        if not self.disagrees:
            return None
        return (
            f"the world's up (z) lies {self.plane_tilt_deg:.1f} degrees from the normal of the largest "
            f"horizontal plane of the points (the floor or a table top: {self.plane_points} of {self.n_points} "
            f"points), more than {WARN_DEG:g}: the world may not be upright (its up came from "
            "noisy point normals); the poses themselves are not judged by this; fix: film more texture on the "
            "floor and walls, or check the scene box and the room's up in the viewer before training"
        )


def check_model_up(reconstruction: pycolmap.Reconstruction) -> UpCheck:
    """``check_up`` of an oriented model's points, stray triangulations left out (as for the scene box)."""
    return check_up(np.asarray(inlier_points(point_cloud(reconstruction)).points))


def check_up(points: np.ndarray, up: np.ndarray | None = None, seed: int = 0) -> UpCheck:
    """The largest plane of ``points`` [N, 3] within ``MAX_TILT_DEG`` of ``up`` (default z) and its angle to it."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    n = len(pts)
    if n < MIN_INLIERS:
        return UpCheck(None, 0, n)
    lo, hi = np.percentile(pts, [5, 95], axis=0)
    tolerance = INLIER_FRACTION * float(np.max(hi - lo))
    rng = np.random.default_rng(seed)
    triples = rng.integers(0, n, size=(HYPOTHESES, 3))
    a, b, c = pts[triples[:, 0]], pts[triples[:, 1]], pts[triples[:, 2]]
    normals = np.cross(b - a, c - a)
    length = np.linalg.norm(normals, axis=1)
    good = length > 1e-12
    normals, a = normals[good] / length[good, None], a[good]
    normals *= np.sign(normals @ up)[:, None]
    near = normals @ up > np.cos(np.radians(MAX_TILT_DEG))
    normals, a = normals[near], a[near]
    if not len(normals):
        return UpCheck(None, 0, n)
    best, best_count = None, 0
    for start in range(0, len(normals), 256):  # [hypotheses, points] in blocks: bounded memory
        d = np.abs(
            (pts @ normals[start : start + 256].T)
            - np.sum(normals[start : start + 256] * a[start : start + 256], axis=1)
        )
        counts = np.count_nonzero(d < tolerance, axis=0)
        i = int(np.argmax(counts))
        if counts[i] > best_count:
            best, best_count = start + i, int(counts[i])
    if best is None or best_count < MIN_INLIERS:
        return UpCheck(None, best_count, n)
    normal, centre = normals[best], a[best]
    for _ in range(3):  # refit to the inliers (least squares), then take the inliers of the refitted plane
        on = np.abs((pts - centre) @ normal) < tolerance
        if np.count_nonzero(on) < 3:
            break
        centre = pts[on].mean(0)
        _, _, vt = np.linalg.svd(pts[on] - centre, full_matrices=False)
        normal = vt[-1] * np.sign(vt[-1] @ up)
    inliers = int(np.count_nonzero(np.abs((pts - centre) @ normal) < tolerance))
    tilt = float(np.degrees(np.arccos(np.clip(normal @ up, -1.0, 1.0))))
    return UpCheck(tilt, inliers, n)
