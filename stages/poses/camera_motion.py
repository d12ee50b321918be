"""Does the camera move? Evidence from COLMAP's feature matches (after matching, before mapping).

The cheaper check before any COLMAP work is ``static_check``; the camera path
of the finished model is judged by ``trajectory_check``.

Triangulation needs a baseline. A tripod shot (or a phone held still) gives
matches that barely move, and COLMAP then fails to initialise or builds a
degenerate model; the user deserves to hear "the camera does not move"
rather than "12 % registered".
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import pycolmap

# pairs whose geometry COLMAP explains by a homography of a rotating camera (no translation)
_ROTATION_ONLY = {pycolmap.TwoViewGeometryConfiguration.PANORAMIC}
_VERIFIED = {
    pycolmap.TwoViewGeometryConfiguration.CALIBRATED,
    pycolmap.TwoViewGeometryConfiguration.UNCALIBRATED,
    pycolmap.TwoViewGeometryConfiguration.PLANAR,
    pycolmap.TwoViewGeometryConfiguration.PANORAMIC,
    pycolmap.TwoViewGeometryConfiguration.PLANAR_OR_PANORAMIC,
}


@dataclass
class FeatureMotion:
    """How far matched features move between frames."""

    n_pairs: int
    """Image pairs with matches that the statistic is taken over."""
    max_median_px: float
    """Largest, over pairs, of the median displacement of matched features (pixels)."""
    rotation_only_fraction: float
    """Fraction of verified pairs COLMAP classified as pure rotation (panoramic)."""

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def feature_motion(database: Path) -> FeatureMotion:
    """Median feature displacement per matched pair, from a COLMAP database after matching.

    Verified inlier matches are used when any pair passed verification; a
    perfectly still camera may fail verification (no epipolar geometry), so
    the raw matches stand in then.
    """
    db = pycolmap.Database.open(database)
    try:
        pair_ids, geometries = db.read_two_view_geometries()
        pairs = [(pid, g.inlier_matches) for pid, g in zip(pair_ids, geometries, strict=True)
                 if g.config in _VERIFIED and len(g.inlier_matches) > 0]
        rotation_only = sum(g.config in _ROTATION_ONLY for g in geometries if g.config in _VERIFIED)
        n_verified = sum(g.config in _VERIFIED for g in geometries)
        if not pairs:
            raw_ids, raw = db.read_all_matches()
            pairs = [(pid, m) for pid, m in zip(raw_ids, raw, strict=True) if len(m) > 0]
        keypoints: dict[int, np.ndarray] = {}
        medians = []
        for pid, matches in pairs:
            i1, i2 = pycolmap.pair_id_to_image_pair(pair_id=pid)
            for i in (i1, i2):
                if i not in keypoints:
                    keypoints[i] = db.read_keypoints(image_id=i)[:, :2]
            m = np.asarray(matches, dtype=np.int64)
            shift = np.linalg.norm(keypoints[i1][m[:, 0]] - keypoints[i2][m[:, 1]], axis=1)
            medians.append(float(np.median(shift)))
    finally:
        db.close()
    return FeatureMotion(n_pairs=len(medians), max_median_px=max(medians, default=0.0),
                         rotation_only_fraction=rotation_only / n_verified if n_verified else 0.0)


def keypoint_counts(database: Path) -> list[int]:
    """SIFT features kept per image (after the object masks), from a COLMAP database after extraction."""
    db = pycolmap.Database.open(database)
    try:
        return [int(db.num_keypoints_for_image(image_id=image.image_id)) for image in db.read_all_images()]
    finally:
        db.close()
