"""Is the reconstructed camera path plausible? Numbers the pose gate judges after structure from motion.

COLMAP can "register" every frame of a clip that no camera path explains: a
tripod clip after a short pan came back as 267/267 frames at 1.10 px, its first
65 cameras up to 36 units from the other 202, which sat within 0.01 of each
other (median point depth 4.75; docs/poses.md). Registration and reprojection error
cannot see that; the camera path can. All lengths are judged against the median
distance from the cameras to the 3D points (the scene depth), so the
numbers read the same whatever scale COLMAP picked (docs/poses.md, "Quality gate"):

- baseline ratio: the widest distance between two cameras over the depth;
- spread ratio: the farthest camera from the middle of the path, over the depth;
- still share: the largest group of cameras on one spot (within
  ``still_radius`` x depth of one camera) over the registered cameras;
- jumps: a step between neighbours in time longer than ``jump_factor`` times
  the typical step (per source frame; at least ``jump_floor`` x depth). A short
  run of cameras that jumps away and back is a jump outlier; a jump that does
  not come back splits the path into pieces.

The verdict: refuse a path that is mostly one spot; drop jump outliers and
the pieces outside the largest one when that one holds a majority of the
cameras (trim); refuse a path broken into pieces none of which holds one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np


@dataclass
class TrajectorySettings:
    """Thresholds of the trajectory gate (``PosesConfig`` carries them; docs/poses.md explains each)."""

    min_baseline_ratio: float = 0.01
    still_radius: float = 0.005
    max_still_share: float = 0.5
    jump_factor: float = 10.0
    jump_floor: float = 0.05
    max_outlier_run: int = 3
    max_spread_ratio: float = 20.0


@dataclass
class TrajectoryJudgement:
    """The numbers the gate judged (written to poses.json) and its verdict."""

    n_frames: int
    """Frames given to structure from motion."""
    n_registered: int
    median_point_depth: float
    max_centre_distance: float
    baseline_ratio: float
    spread_ratio: float
    """Largest distance of a camera from the median camera centre, over the depth."""
    largest_model_share: float
    """Frames in the model that was kept, over all frames."""
    model_sizes: list[int]
    still_share: float
    still_frames: list[str]
    still_spread: float
    """Largest distance between two cameras of the still group (model units)."""
    moving_reach: float
    """Farthest distance of a camera outside the still group from the group's centre (model units)."""
    moving_usable: bool
    """The cameras outside the still group are 3 or more, one run in time, with a baseline of their own."""
    typical_step: float
    """Median distance between cameras neighbouring in time, per source frame, over the steps longer than the
    still radius (all steps when none is; model units)."""
    jump_limit: float
    """A step per source frame longer than this is a jump (model units; grows with the frame gap)."""
    max_step_ratio: float
    """The longest step per source frame over the typical one (jumps start at ``jump_factor``)."""
    jump_outliers: list[str]
    pieces: list[list[str]]
    """The path split at jumps that do not come back (first and last frame, in time order)."""
    piece_sizes: list[int]
    trimmed: list[str]
    kept_baseline_ratio: float
    """``baseline_ratio`` of the cameras the verdict keeps."""
    verdict: str
    """``pass``, ``trim`` (frames in ``trimmed`` are dropped) or ``refuse``."""
    reason: str
    """``static``, ``mostly still``, ``broken path``, ``static after trim``, ``jumps`` (trim) or empty."""
    limits: dict[str, float] = field(default_factory=dict)
    """The thresholds judged against."""
    kept: list[str] = field(default_factory=list)
    """Frames the verdict keeps (not in poses.json: ``registered`` there lists them)."""
    order: list[str] = field(default_factory=list)
    """Registered frames in time order (not in poses.json)."""

    def as_dict(self) -> dict[str, object]:
        out = asdict(self)
        out.pop("kept")
        out.pop("order")
        return out


def diameter(points: np.ndarray) -> float:
    """Largest distance between two of ``points`` (blocks of 512 rows keep memory flat for long clips)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    best = 0.0
    for start in range(0, len(points), 512):
        d = np.linalg.norm(points[start:start + 512, None] - points[None], axis=-1)
        best = max(best, float(d.max(initial=0.0)))
    return best


def _still_group(centres: np.ndarray, radius: float) -> np.ndarray:
    """Indices of the largest set of cameras within ``radius`` of one of them."""
    best = np.empty(0, dtype=np.int64)
    for start in range(0, len(centres), 512):  # blocks keep the distance matrix small for long clips
        d = np.linalg.norm(centres[start:start + 512, None] - centres[None], axis=-1)
        counts = (d <= radius).sum(1)
        k = int(np.argmax(counts))
        if counts[k] > len(best):
            best = np.flatnonzero(d[k] <= radius)
    return best


def median_point_depth(centres: np.ndarray, points: np.ndarray) -> float:
    """Median distance between (a sample of) the cameras and (a sample of) the 3D points."""
    if len(centres) == 0 or len(points) == 0:
        return 0.0
    sample = points[:: max(1, len(points) // 2000)]
    cams = centres[:: max(1, len(centres) // 50)]
    return float(np.median(np.linalg.norm(sample[None] - cams[:, None], axis=-1)))


def judge_trajectory(names: list[str], centres: np.ndarray, times: np.ndarray, depth: float, n_frames: int,
                     model_sizes: list[int], settings: TrajectorySettings | None = None) -> TrajectoryJudgement:
    """Judge the camera path ``centres`` of the registered frames ``names``, given in time order.

    ``times``: source-frame index of each camera (gaps in it widen the allowed step).
    """
    s = settings or TrajectorySettings()
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    times = np.asarray(times, dtype=np.float64)
    n = len(names)
    span = diameter(centres)
    middle = np.median(centres, axis=0) if n else np.zeros(3)
    reach = float(np.max(np.linalg.norm(centres - middle, axis=1))) if n else 0.0
    base = {"n_frames": n_frames, "n_registered": n, "median_point_depth": depth, "max_centre_distance": span,
            "baseline_ratio": span / depth if depth > 0 else 0.0, "spread_ratio": reach / depth if depth > 0 else 0.0,
            "largest_model_share": n / n_frames if n_frames else 0.0, "model_sizes": list(model_sizes)}
    base["limits"] = asdict(s)
    base["order"] = list(names)
    if n < 3 or depth <= 0:
        return TrajectoryJudgement(**base, still_share=0.0, still_frames=[], still_spread=0.0, moving_reach=0.0,
                                   moving_usable=False, typical_step=0.0, jump_limit=0.0, max_step_ratio=0.0,
                                   jump_outliers=[],
                                   pieces=[], piece_sizes=[], trimmed=[], kept_baseline_ratio=base["baseline_ratio"],
                                   verdict="pass",
                                   reason="too few cameras or points to judge the path", kept=list(names))

    still = _still_group(centres, s.still_radius * depth)
    still_spread = diameter(centres[still])
    still_share = len(still) / n
    moving = np.setdiff1d(np.arange(n), still)
    moving_reach = float(np.max(np.linalg.norm(centres[moving] - centres[still].mean(0), axis=1), initial=0.0))
    moving_usable = bool(len(moving) >= 3 and np.all(np.diff(moving) == 1)
                         and diameter(centres[moving]) / depth >= s.min_baseline_ratio)

    gaps = np.maximum(np.diff(times), 1.0)
    per_frame = np.linalg.norm(np.diff(centres, axis=0), axis=1) / gaps
    # the typical step of the camera when it moves: a clip that rests part of the time must not make every
    # real step look like a jump
    moving_steps = per_frame[per_frame > s.still_radius * depth]
    typical = float(np.median(moving_steps if len(moving_steps) else per_frame))
    limit = max(s.jump_factor * typical, s.jump_floor * depth)
    outliers = _jump_outliers(centres, times, limit, s.max_outlier_run)
    keep = np.setdiff1d(np.arange(n), outliers)
    pieces = _split(keep, centres, times, limit)
    largest = max(pieces, key=len)
    judged = {**base, "still_share": still_share, "still_frames": [names[i] for i in still],
              "still_spread": still_spread, "moving_reach": moving_reach, "moving_usable": moving_usable,
              "typical_step": typical, "jump_limit": limit,
              "max_step_ratio": float(per_frame.max() / typical) if typical > 0 else 0.0,
              "jump_outliers": [names[i] for i in outliers],
              "pieces": [[names[p[0]], names[p[-1]]] for p in pieces], "piece_sizes": [len(p) for p in pieces]}

    ratio = base["baseline_ratio"]
    if ratio < s.min_baseline_ratio:
        return TrajectoryJudgement(**judged, trimmed=[], kept_baseline_ratio=ratio, verdict="refuse",
                                   reason="static", kept=[])
    if still_share > s.max_still_share:
        return TrajectoryJudgement(**judged, trimmed=[], kept_baseline_ratio=ratio, verdict="refuse",
                                   reason="mostly still", kept=[])
    if len(pieces) > 1 and len(largest) <= n / 2:
        return TrajectoryJudgement(**judged, trimmed=[], kept_baseline_ratio=ratio, verdict="refuse",
                                   reason="broken path", kept=[])
    kept_idx = set(largest.tolist())
    trimmed = [names[i] for i in range(n) if i not in kept_idx]
    kept = [names[i] for i in range(n) if i in kept_idx]
    if not trimmed:
        return TrajectoryJudgement(**judged, trimmed=[], kept_baseline_ratio=ratio, verdict="pass", reason="",
                                   kept=kept)
    kept_ratio = diameter(centres[sorted(kept_idx)]) / depth
    if kept_ratio < s.min_baseline_ratio:
        return TrajectoryJudgement(**judged, trimmed=trimmed, kept_baseline_ratio=kept_ratio, verdict="refuse",
                                   reason="static after trim", kept=kept)
    return TrajectoryJudgement(**judged, trimmed=trimmed, kept_baseline_ratio=kept_ratio, verdict="trim",
                               reason="jumps", kept=kept)


def _jump_outliers(centres: np.ndarray, times: np.ndarray, limit: float, max_run: int) -> np.ndarray:
    """Short runs of cameras that jump away from the path and back: their neighbours either side are close."""
    n = len(centres)
    out: list[int] = []

    def far(i: int, j: int) -> bool:
        return float(np.linalg.norm(centres[j] - centres[i])) > limit * max(times[j] - times[i], 1.0)

    i = 1
    while i < n - 1:
        if far(i - 1, i):
            for length in range(1, max_run + 1):
                end = i + length  # first camera after the run
                if end >= n:
                    break
                if far(end - 1, end) and not far(i - 1, end):
                    out.extend(range(i, end))
                    i = end
                    break
        i += 1
    return np.asarray(out, dtype=np.int64)


def _split(keep: np.ndarray, centres: np.ndarray, times: np.ndarray, limit: float) -> list[np.ndarray]:
    """``keep`` (indices in time order) cut wherever a step is a jump."""
    if len(keep) == 0:
        return [keep]
    c, t = centres[keep], times[keep]
    steps = np.linalg.norm(np.diff(c, axis=0), axis=1)
    cuts = np.flatnonzero(steps > limit * np.maximum(np.diff(t), 1.0)) + 1
    return np.split(keep, cuts)
