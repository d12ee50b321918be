"""Scene normalisation: a similarity transform that maps the scene box into [-1, 1]^3."""

from __future__ import annotations

import numpy as np


def box_to_unit_transform(box_min: np.ndarray, box_max: np.ndarray) -> np.ndarray:
    """4x4 similarity ``x' = s (x - c)`` mapping the box into [-1, 1]^3 (uniform scale, longest side fits)."""
    box_min, box_max = np.asarray(box_min, float), np.asarray(box_max, float)
    extent = float(np.max(box_max - box_min))
    if not np.isfinite(extent) or extent <= 0:
        raise ValueError(f"scene box {box_min.tolist()} .. {box_max.tolist()} is empty or not finite")
    s = 2.0 / extent
    c = 0.5 * (box_min + box_max)
    t = np.eye(4)
    t[:3, :3] *= s
    t[:3, 3] = -s * c
    return t


def apply_similarity_to_pose(transform: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Move a camera-to-world pose by a similarity; the rotation stays orthonormal."""
    s = np.cbrt(np.linalg.det(transform[:3, :3]))
    out = transform @ c2w
    out[:3, :3] /= s
    return out


def apply_similarity_to_points(transform: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.asarray(points, float) @ transform[:3, :3].T + transform[:3, 3]


def camera_bounds_box(centres: np.ndarray, margin: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A box around camera centres, padded by ``margin`` of its extent (used when no points exist)."""
    lo, hi = centres.min(0), centres.max(0)
    pad = margin * float(np.max(hi - lo) or 1.0)
    return lo - pad, hi + pad
