"""The quality gate: refuse a pose result that later stages cannot use, and say what to try."""

from __future__ import annotations

import math
from pathlib import Path

from stages.scene import frame_id_of

from .camera_motion import Baseline, FeatureMotion
from .errors import PoseQualityError, StaticCameraError

REGISTRATION_ADVICE = (
    "try `--matcher exhaustive` (pairs every frame with every other), capture with more overlap "
    "(slower camera motion, or extract more frames with a smaller `livescene frames --stride`), "
    "and sharper frames (check the sharpness column of frames.csv; avoid motion blur); "
    "textureless walls need some texture in view"
)
STATIC_ADVICE = (
    "move the camera through the room (walk around, do not only turn on the spot): COLMAP needs "
    "translation between frames to triangulate; a fixed camera cannot be posed by structure from motion"
)


def compact_names(names: list[str], limit: int = 40) -> str:
    """``frame_00003..frame_00007, frame_00012`` : consecutive frame ids as ranges, at most ``limit`` items."""
    items: list[str] = []
    run: list[tuple[int, str]] = []

    def flush() -> None:
        if run:
            items.append(run[0][1] if len(run) == 1 else f"{run[0][1]}..{run[-1][1]} ({len(run)})")
            run.clear()

    for name in names:
        fid = frame_id_of(Path(name).stem)
        idx = int(fid) if fid.isdigit() else None
        stem = Path(name).stem
        if run and idx is not None and run[-1][0] is not None and idx - run[-1][0] <= 1:
            run.append((idx, stem))
        else:
            flush()
            run.append((idx, stem))  # type: ignore[arg-type]
    flush()
    shown = ", ".join(items[:limit])
    return shown + (f", ... ({len(items) - limit} more runs)" if len(items) > limit else "")


def check_motion(motion: FeatureMotion, image_diagonal: float, min_fraction: float, frames_dir: Path) -> None:
    """Raise StaticCameraError when matched features barely move between any two frames."""
    if motion.n_pairs == 0:
        return  # nothing matched at all: the registration gate reports it with its own advice
    limit = min_fraction * image_diagonal
    if motion.max_median_px < limit:
        raise StaticCameraError(
            frames_dir,
            f"the camera does not move: between every pair of frames matched features shift by at most "
            f"{motion.max_median_px:.2f} px (median; {motion.n_pairs} pairs), below {limit:.2f} px "
            f"({min_fraction:.1%} of the image diagonal), so there is no baseline to triangulate from",
            STATIC_ADVICE,
        )


def check_baseline(baseline: Baseline, motion: FeatureMotion, frames_dir: Path, min_ratio: float = 0.01) -> None:
    """Raise StaticCameraError for a model whose cameras sit (almost) on one spot."""
    if baseline.median_depth > 0 and baseline.ratio < min_ratio:
        rotation = (f"; {motion.rotation_only_fraction:.0%} of matched pairs look like a camera turning on the "
                    "spot") if motion.rotation_only_fraction > 0 else ""
        raise StaticCameraError(
            frames_dir,
            f"the camera does not move: all reconstructed camera centres lie within {baseline.ratio:.2%} of the "
            f"scene depth of each other{rotation}, so the poses are degenerate",
            STATIC_ADVICE,
        )


def check_registration(names: list[str], registered: set[str], min_fraction: float, frames_dir: Path,
                       detail: str = "") -> float:
    """The registered fraction; raise PoseQualityError listing unregistered frames when it is too low."""
    fraction = len(registered) / len(names) if names else 0.0
    if fraction < min_fraction:
        missing = [n for n in names if n not in registered]
        raise PoseQualityError(
            frames_dir,
            f"only {len(registered)} of {len(names)} frames ({fraction:.0%}) received a pose, below the "
            f"required {min_fraction:.0%}{detail}; unregistered frames: {compact_names(missing)}",
            REGISTRATION_ADVICE + " (or lower --min-registered if a partial model is acceptable)",
        )
    return fraction


def intrinsics_warnings(fx: float, fy: float, width: int, height: int) -> list[str]:
    """Signs of an under-constrained camera that the registration gate cannot see.

    With a separate fy (PINHOLE, OPENCV) and a camera that only moves sideways,
    bundle adjustment can drift fy far from fx while the reprojection error
    stays small: every frame registers, but the intrinsics are useless.
    """
    out = []
    if not 0.8 <= fx / fy <= 1.25:
        out.append(f"fx = {fx:.1f} px and fy = {fy:.1f} px differ by more than 25%: the camera model is "
                   "under-constrained by this motion; use --camera-model SIMPLE_RADIAL or SIMPLE_PINHOLE "
                   "(one focal length)")
    fov = 2 * math.degrees(math.atan(0.5 * width / fx))
    if not 20.0 <= fov <= 150.0:
        out.append(f"the estimated horizontal field of view is {fov:.0f} degrees, outside 20..150: check the "
                   "focal length before using these poses")
    return out
