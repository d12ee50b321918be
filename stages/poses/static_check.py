"""Does the camera move at all? A check from cheap feature motion, before structure from motion.

COLMAP on a still clip spends minutes (2.6 min on a 267-frame 640x480 clip; docs/poses.md, "Quality gate")
before it fails to triangulate. Tracking corners between a couple of dozen sampled
frames on small grey images takes about a second and tells the same thing:
a camera that does not move leaves the background where it was.

Per pair of sampled frames (neighbours in time, plus a few long-range pairs):
Shi-Tomasi corners, pyramidal Lucas-Kanade flow with a forward-backward check,
and the displacement of the *stillest* 30 % of the tracked corners, so that a
person moving in front of a tripod does not count as camera motion. A pair
whose tracking is lost counts as moving (permissive: the clip then goes to
COLMAP). The clip is refused only when every pair is still (docs/poses.md,
"Quality gate").

For pairs that move, the parallax left after the best homography (over the
corners consistent with one epipolar geometry) tells a camera that translates
from one that only turns on the spot: recorded, and used by the messages.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from .colmap_masks import index_masks, mask_key, object_pixels

MAX_SAMPLED_FRAMES = 24
"""Frames sampled evenly over the clip (a dozen pairs of neighbours are enough to see motion)."""
LONG_SIDE_PX = 512
"""Frames are shrunk to this longest side before tracking (seconds for any input size)."""
STILL_QUANTILE = 0.3
"""The stillest 30 % of the tracked corners stand for the background."""
MIN_TRACKED = 20
"""A pair with fewer tracked corners has lost tracking: it moved. (A share would misjudge a person crossing
a still view: the background's few corners still track, and they are what counts.)"""
PARALLAX_QUANTILE = 0.75


@dataclass
class PairMotion:
    """Motion of the tracked corners between two sampled frames (pixels of the shrunk images)."""

    first: str
    second: str
    n_corners: int
    n_tracked: int
    still_px: float | None
    """30th percentile of the corner displacement; None when tracking was lost (counts as moving)."""
    median_px: float | None
    parallax_px: float | None
    """75th percentile of the distance to the best homography, over corners fitting one epipolar geometry."""


@dataclass
class MotionPrecheck:
    """What the pre-SfM motion check measured."""

    n_frames_sampled: int
    n_pairs: int
    """Pairs with corners to track (a textureless clip has none: no verdict, COLMAP reports it)."""
    long_side_px: int
    still_threshold_px: float
    """A pair is still when its background moves less than this (``static_motion_fraction`` of the diagonal)."""
    n_lost: int
    """Pairs whose tracking was lost (the view changed too much: they count as moving)."""
    max_still_px: float | None
    """Largest background displacement over the pairs that kept tracking."""
    still_pair_fraction: float
    """Share of neighbouring sampled pairs that are still."""
    still_frames: list[str]
    """Sampled frames whose pair with the next sampled frame is still."""
    still_spans: list[str]
    """Those pairs merged into spans of the clip, ``frame_00019..frame_00057``."""
    parallax_threshold_px: float
    rotation_only_fraction: float | None
    """Among moving pairs with a parallax measure, the share whose motion a homography explains
    (a camera turning on the spot, or a flat scene); None when no moving pair was measured."""
    seconds: float
    pairs: list[PairMotion] = field(default_factory=list)

    @property
    def static(self) -> bool:
        """Every pair with corners is still: the camera does not move."""
        return (self.n_pairs > 0 and self.n_lost == 0 and self.max_still_px is not None
                and self.max_still_px < self.still_threshold_px)

    def as_dict(self) -> dict[str, object]:
        out = asdict(self)
        out["static"] = self.static
        return out


def sample_indices(n: int, k: int = MAX_SAMPLED_FRAMES) -> list[int]:
    """``k`` indices spread evenly over ``range(n)``, first and last included."""
    if n <= k:
        return list(range(n))
    return sorted({round(i * (n - 1) / (k - 1)) for i in range(k)})


def _pairs(m: int) -> list[tuple[int, int]]:
    """Neighbours in time, then long-range pairs (a slow camera shows its motion over the whole clip)."""
    out = [(i, i + 1) for i in range(m - 1)]
    for a, b in ((0, m // 2), (m // 2, m - 1), (0, m - 1)):
        if b - a > 1 and (a, b) not in out:
            out.append((a, b))
    return out


def _read_small(path: Path, long_side: int) -> np.ndarray | None:
    """Grey image shrunk to ``long_side`` pixels (None when unreadable)."""
    full = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if full is None:
        return None
    scale = long_side / max(full.shape)
    if scale >= 1.0:
        return full
    return cv2.resize(full, (round(full.shape[1] * scale), round(full.shape[0] * scale)), interpolation=cv2.INTER_AREA)


def _track(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, int]:
    """Corners of ``a`` and where LK puts them in ``b``, forward-backward consistent to 0.5 px."""
    corners = cv2.goodFeaturesToTrack(a, maxCorners=500, qualityLevel=0.01, minDistance=7, mask=mask,
                                      blockSize=7)
    if corners is None:
        return np.empty((0, 2), np.float32), np.empty((0, 2), np.float32), 0
    lk = {"winSize": (21, 21), "maxLevel": 4,
          "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)}
    fwd, st1, _ = cv2.calcOpticalFlowPyrLK(a, b, corners, None, **lk)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(b, a, fwd, None, **lk)
    ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm((back - corners).reshape(-1, 2), axis=1) < 0.5)
    return corners.reshape(-1, 2)[ok], fwd.reshape(-1, 2)[ok], len(corners)


def _parallax(p0: np.ndarray, p1: np.ndarray) -> float | None:
    """Distance to the best homography, over the corners that fit one fundamental matrix."""
    if len(p0) < 15:
        return None
    f, inl = cv2.findFundamentalMat(p0, p1, cv2.FM_RANSAC, 1.0, 0.99)
    if f is None or inl is None or int(inl.sum()) < 15:
        return None
    q0, q1 = p0[inl.ravel() == 1], p1[inl.ravel() == 1]
    h, _ = cv2.findHomography(q0, q1, cv2.RANSAC, 1.0)
    if h is None:
        return None
    mapped = cv2.perspectiveTransform(q0.reshape(-1, 1, 2), h).reshape(-1, 2)
    return float(np.quantile(np.linalg.norm(mapped - q1, axis=1), PARALLAX_QUANTILE))


def _static_scene_mask(masks: dict[str, Path] | None, name: str, shape: tuple[int, int]) -> np.ndarray | None:
    """255 where the scene is static (interactive objects move on their own), None without a mask."""
    if masks is None or (path := masks.get(mask_key(Path(name).stem))) is None:
        return None
    objects = cv2.resize(object_pixels(path).astype(np.uint8), (shape[1], shape[0]),
                         interpolation=cv2.INTER_NEAREST)
    return np.where(objects > 0, 0, 255).astype(np.uint8)


def _spans(pairs: list[PairMotion]) -> list[str]:
    """Neighbouring still pairs merged: (a, b), (b, c) -> ``a..c``."""
    spans: list[list[str]] = []
    for p in pairs:
        if spans and spans[-1][1] == p.first:
            spans[-1][1] = p.second
        else:
            spans.append([p.first, p.second])
    return [f"{Path(a).stem}..{Path(b).stem}" for a, b in spans]


def measure_motion(image_dir: Path, names: list[str], static_motion_fraction: float,
                   masks_dir: Path | None = None, max_frames: int = MAX_SAMPLED_FRAMES,
                   long_side: int = LONG_SIDE_PX) -> MotionPrecheck:
    """Track corners between sampled frames of ``names`` (in time order) and measure how the camera moves."""
    t0 = time.perf_counter()
    picked = [names[i] for i in sample_indices(len(names), max_frames)]
    masks = index_masks(masks_dir) if masks_dir is not None else None
    images = [_read_small(image_dir / name, long_side) for name in picked]
    shape = next((im.shape for im in images if im is not None), (long_side, long_side))
    threshold = static_motion_fraction * float(np.hypot(*shape))
    parallax_threshold = threshold  # the same fraction of the diagonal: below it, a homography explains the pair
    pairs: list[PairMotion] = []
    for i, j in _pairs(len(picked)):
        a, b = images[i], images[j]
        if a is None or b is None or a.shape != b.shape:
            continue  # unreadable or odd-sized frames: the SfM stage names them
        p0, p1, n_corners = _track(a, b, _static_scene_mask(masks, picked[i], a.shape))
        if n_corners == 0:
            continue
        lost = len(p0) < MIN_TRACKED
        shift = np.linalg.norm(p1 - p0, axis=1)
        pairs.append(PairMotion(
            first=picked[i], second=picked[j], n_corners=n_corners, n_tracked=len(p0),
            still_px=None if lost else float(np.quantile(shift, STILL_QUANTILE)),
            median_px=None if lost else float(np.median(shift)),
            parallax_px=None if lost else _parallax(p0, p1)))
    still_values = [p.still_px for p in pairs if p.still_px is not None]
    neighbours = [p for p in pairs if picked.index(p.second) - picked.index(p.first) == 1]
    still = [p for p in neighbours if p.still_px is not None and p.still_px < threshold]
    moving_measured = [p for p in pairs if p.parallax_px is not None and p.still_px is not None
                       and p.still_px >= threshold]
    return MotionPrecheck(
        n_frames_sampled=len(picked), n_pairs=len(pairs), long_side_px=int(max(shape)),
        still_threshold_px=threshold, n_lost=len(pairs) - len(still_values),
        max_still_px=max(still_values) if still_values else None,
        still_pair_fraction=len(still) / len(neighbours) if neighbours else 0.0,
        still_frames=[p.first for p in still], still_spans=_spans(still), parallax_threshold_px=parallax_threshold,
        rotation_only_fraction=(sum(p.parallax_px < parallax_threshold for p in moving_measured)  # type: ignore[operator]
                                / len(moving_measured)) if moving_measured else None,
        seconds=time.perf_counter() - t0, pairs=pairs)
