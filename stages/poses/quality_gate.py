"""The quality gate: refuse a pose result that later stages cannot use, and say what to try."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from stages.scene import frame_id_of

from .camera_motion import FeatureMotion
from .config import PosesConfig
from .errors import DegenerateTrajectoryError, PoseQualityError, StaticCameraError
from .frame_list import frames_summary
from .static_check import MotionPrecheck
from .trajectory_check import TrajectoryJudgement, TrajectorySettings

STATIC_ADVICE = (
    "move the camera through the room (walk around, do not only turn on the spot): COLMAP needs "
    "translation between frames to triangulate; a fixed camera cannot be posed by structure from motion"
)

INIT_MIN_INLIERS = 100
"""Verified matches COLMAP's mapper needs between two frames to start a model (pycolmap 4.2.1,
``IncrementalMapperOptions.init_min_num_inliers``)."""
FEW_FEATURES = 2 * INIT_MIN_INLIERS
"""A failed registration whose frames keep a median of fewer SIFT features than this is put down to the frames
first (too little texture, or masks over most of the view), not to the matching (docs/poses.md, Quality gate)."""


def frames_all_kept(frames_dir: Path) -> bool:
    """Whether `livescene frames` already kept every source frame (then a smaller --stride is no fix)."""
    info = frames_summary(frames_dir)
    try:
        return int(info["n_frames"]) >= int(info["decoded_frame_count"])
    except (ValueError, KeyError, TypeError):
        return False


def registration_advice(cfg: PosesConfig, matcher: str) -> str:
    """What to try after a registration failure, leaving out what this run already did."""
    tries = []
    if matcher != "exhaustive":
        tries.append("`--matcher exhaustive` (pairs every frame with every other)")
    if matcher == "sequential" and cfg.sequential_overlap <= PosesConfig.sequential_overlap:
        tries.append(f"a larger `--overlap` (now {cfg.sequential_overlap})")
    overlap = "capture with more overlap (slower camera motion"
    overlap += ")" if frames_all_kept(cfg.frames_dir) else \
        ", or extract more frames with a smaller `livescene frames --stride`)"
    tries.append(overlap)
    tries.append("sharper frames (check the sharpness column of frames.csv; avoid motion blur)")
    advice = "try " + ", ".join(tries) + "; textureless walls need some texture in view"
    if cfg.min_registered > 0.5:
        advice += f" (or lower --min-registered, now {cfg.min_registered:g}, if a partial model is acceptable)"
    return advice


def feature_shortage(counts: list[int], masked_fraction: float | None) -> tuple[str, str] | None:
    """``(detail, advice)`` for a failed registration whose frames hold few features, else None.

    ``counts``: SIFT features kept per frame (after the object masks); ``masked_fraction``: the share of a frame
    the (dilated) object masks hide on average, None without masks.
    """
    if not counts:
        return None
    median = statistics.median(counts)
    if median >= FEW_FEATURES:
        return None
    masks = "" if masked_fraction is None else \
        f" outside the object masks, which hide {masked_fraction:.0%} of a frame on average"
    detail = (f" (the frames hold few features: SIFT kept a median of {median:.0f} per frame ({min(counts)} in the "
              f"poorest){masks}; COLMAP starts a model from {INIT_MIN_INLIERS} verified matches between two frames)")
    if masked_fraction is not None and masked_fraction > 0.5:
        advice = ("the moving objects fill most of the view: film with more of the static room in view (step back "
                  "from them, or use a wider lens)")
    else:
        advice = ("film with more texture in view: plain walls and large plain furniture give SIFT little to match "
                  "(keep patterned surfaces, shelves or pictures in the frame)")
    return detail, advice


def too_few_frames_advice(frames_dir: Path) -> str:
    if frames_all_kept(frames_dir):
        return "film a longer clip (every frame of this one is already extracted)"
    return "extract more frames (`livescene frames --stride 1`)"


def compact_names(names: list[str], limit: int = 40, order: list[str] | None = None) -> str:
    """``frame_00003..frame_00007 (5), frame_00012``: runs of frames as ranges, at most ``limit`` items.

    A run is consecutive frame ids, or, with ``order`` (every frame in playback order), consecutive
    positions in it: frames 1, 2, 4, 7 of a clip that skips 3, 5 and 6 are one run then.
    """
    position = {n: k for k, n in enumerate(order)} if order is not None else None
    items: list[str] = []
    run: list[tuple[int | None, str]] = []

    def flush() -> None:
        if run:
            items.append(run[0][1] if len(run) == 1 else f"{run[0][1]}..{run[-1][1]} ({len(run)})")
            run.clear()

    for name in names:
        if position is not None:
            idx = position.get(name)
        else:
            fid = frame_id_of(Path(name).stem)
            idx = int(fid) if fid.isdigit() else None
        stem = Path(name).stem
        previous = run[-1][0] if run else None
        if idx is not None and previous is not None and 0 <= idx - previous <= 1:
            run.append((idx, stem))
        else:
            flush()
            run.append((idx, stem))
    flush()
    shown = ", ".join(items[:limit])
    return shown + (f", ... ({len(items) - limit} more runs)" if len(items) > limit else "")


def split_model_warning(n_models: int, left_out: list[str], ordered: list[str], advice: str) -> str | None:
    """The warning for a run that passed the registration gate although COLMAP's frames broke into ``n_models``
    separate models: only the largest is kept, so ``left_out`` (the frames the kept model does not pose: those of
    the other models and any that no model posed, in playback ``ordered``) are missing from the dataset; a user
    should know which, and why. COLMAP does not say which model a left-out frame was in, so neither does this.
    None when the kept model poses every frame: COLMAP then made a second model of frames the first one also posed
    (seen on a blurred handheld capture: 100 of 100 frames in the largest of two), and nothing is lost."""
    if n_models <= 1 or not left_out:
        return None
    which = compact_names(left_out, limit=8, order=ordered)
    return (f"COLMAP's frames broke into {n_models} separate models (no shared features join them: a cut, a jump or "
            f"a stretch without texture); the largest is kept, and the {len(left_out)} frame(s) it does not pose (of "
            f"the other models, or of none) are left out: {which}. To keep them, {advice}")


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


def check_precheck(pre: MotionPrecheck, names: list[str], frames_dir: Path) -> None:
    """Raise StaticCameraError when the pre-SfM feature tracks show a camera that never moves."""
    if not pre.static:
        return
    raise StaticCameraError(
        frames_dir,
        f"the camera does not move: in frames {Path(names[0]).stem}..{Path(names[-1]).stem} "
        f"({len(names)} frames) the background shifts by at most {pre.max_still_px:.2f} px between any two of "
        f"{pre.n_frames_sampled} sampled frames ({pre.n_pairs} pairs, images shrunk to {pre.long_side_px} px; "
        f"{pre.still_threshold_px:.2f} px = the still limit), so there is no baseline to triangulate from "
        f"(found in {pre.seconds:.1f} s, before structure from motion)",
        STATIC_ADVICE,
    )


def check_trajectory(judged: TrajectoryJudgement, frames_dir: Path, settings: TrajectorySettings, broken_fix: str,
                     motion: FeatureMotion | None = None, pre: MotionPrecheck | None = None) -> list[str]:
    """Raise for an implausible camera path; return warnings (trimmed frames, a very wide path).

    ``frames_dir`` is named in the errors; ``broken_fix`` is the advice for a path in pieces (what structure
    from motion could try, or how to remake an imported model); ``motion`` and ``pre`` are the feature tracks
    of a run of structure from motion (an imported model has none)."""
    depth = judged.median_point_depth
    if judged.verdict == "refuse" and judged.reason in ("static", "static after trim"):
        rotation = (f"; {motion.rotation_only_fraction:.0%} of matched pairs look like a camera turning on the "
                    "spot") if motion is not None and motion.rotation_only_fraction > 0 else ""
        which = "all reconstructed camera centres" if judged.reason == "static" else \
            f"after dropping the jumping frames {compact_names(judged.trimmed, order=judged.order)}, the other " \
            "camera centres"
        raise StaticCameraError(
            frames_dir,
            f"the camera does not move: {which} lie within {judged.kept_baseline_ratio:.2%} of the scene depth "
            f"(median point depth {depth:.3g}) of each other{rotation}, so the poses are degenerate",
            STATIC_ADVICE,
        )
    if judged.verdict == "refuse" and judged.reason == "mostly still":
        still = set(judged.still_frames)
        moving = [n for n in judged.order if n not in still]
        raise DegenerateTrajectoryError(frames_dir, _mostly_still_problem(judged, moving, pre),
                                        _mostly_still_fix(judged, moving, pre))
    if judged.verdict == "refuse" and judged.reason == "broken path":
        pieces = "; ".join(f"{a}..{b} ({k})" if a != b else f"{a} (1)"
                           for (a, b), k in zip(judged.pieces, judged.piece_sizes, strict=True))
        raise DegenerateTrajectoryError(
            frames_dir,
            f"the camera path breaks into {len(judged.pieces)} pieces at jumps longer than {judged.jump_limit:.3g} "
            f"units per frame ({settings.jump_factor:g} x the typical step {judged.typical_step:.3g}; median point "
            f"depth {depth:.3g}) and none holds a majority of the {judged.n_registered} cameras: {pieces}",
            "the pieces do not connect: " + broken_fix,
        )
    out = []
    if judged.verdict == "trim":
        trimmed = compact_names(judged.trimmed, order=judged.order)
        out.append(f"dropped {len(judged.trimmed)} frame(s) whose cameras jump away from their neighbours in time "
                   f"({trimmed}): steps longer than {judged.jump_limit:.3g} units per frame "
                   f"({settings.jump_factor:g} x the typical step, median point depth {depth:.3g}); they get no pose")
    if judged.spread_ratio > settings.max_spread_ratio:
        out.append(f"a camera lies {judged.spread_ratio:.1f} median point depths from the middle of the path "
                   f"(limit {settings.max_spread_ratio:g}): check the poses before training on them")
    return out


def _mostly_still_problem(judged: TrajectoryJudgement, moving: list[str], pre: MotionPrecheck | None) -> str:
    k, n = len(judged.still_frames), judged.n_registered
    spot = (f"the other {k} cameras ({compact_names(judged.still_frames, 6, judged.order)}), which sit within "
            f"{judged.still_spread:.3g} units of each other (median point depth {judged.median_point_depth:.3g})")
    if moving:
        head = f"frames {compact_names(moving, 6, judged.order)} lie up to {judged.moving_reach:.3g} units from {spot}"
    else:
        head = f"{spot[len('the other '):]}"
    turn = ""
    if _turns_on_the_spot(pre):
        turn = "; the frames that move show no parallax (a camera turning on the spot)"
    limit = judged.limits["max_still_share"]
    return (f"{head}: {k} of {n} registered frames ({k / n:.0%}, above {limit:.0%}) were filmed from one spot"
            f", as in a tripod clip with a short pan{turn}, so most frames add no baseline and the "
            "poses cannot be trusted")


def _turns_on_the_spot(pre: MotionPrecheck | None) -> bool:
    """Every sampled pair that moves fits a homography: rotation without translation (or a flat scene)."""
    return pre is not None and pre.rotation_only_fraction == 1.0


def _mostly_still_fix(judged: TrajectoryJudgement, moving: list[str], pre: MotionPrecheck | None) -> str:
    fix = ("film the scene moving around the room (walk the camera along it, do not only turn it; a camera on a "
           "tripod cannot be posed by structure from motion)")
    # the moving frames alone only help when they translate: a pan's model baseline is COLMAP's guess
    if judged.moving_usable and not _turns_on_the_spot(pre):
        fix += (f", or cut the clip to the frames where the camera moves ({compact_names(moving, 6, judged.order)}) "
                "and run `livescene frames` on that part")
    return fix


def blank_frames_note(frames_dir: Path, unregistered: list[str]) -> str:
    """What a registration error adds when some frames it could not pose are ones `livescene frames` found blank
    (frames.json ``blank_frames``: almost one grey level, a lens cover): their cause is the frames, not the matching."""
    blank = frames_summary(frames_dir).get("blank_frames") or []
    hit = [n for n in unregistered if n in blank]
    if not hit:
        return ""
    return (f" ({len(hit)} of them hold almost one grey level, as `livescene frames` warned: {compact_names(hit)}; "
            "a lens cover or a blank screen has nothing to match: cut them from the video)")


def check_registration(names: list[str], registered: set[str], min_fraction: float, frames_dir: Path,
                       detail: str = "", advice: str = "") -> float:
    """The registered fraction; raise PoseQualityError listing unregistered frames when it is too low."""
    fraction = len(registered) / len(names) if names else 0.0
    if fraction < min_fraction:
        missing = [n for n in names if n not in registered]
        raise PoseQualityError(
            frames_dir,
            f"only {len(registered)} of {len(names)} frames ({fraction:.0%}) received a pose, below the "
            f"required {min_fraction:.0%}{detail}; unregistered frames: {compact_names(missing)}",
            advice or "try `--matcher exhaustive`, more overlap between frames, sharper frames, texture in view",
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
