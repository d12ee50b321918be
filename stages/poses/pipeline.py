"""The pose stage end to end: frames (+ masks) -> COLMAP model, transforms.json, point cloud, scene box."""

from __future__ import annotations

import shutil
import sys
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pycolmap

from stages.scene import atomic_dir, write_json

from .camera_motion import FeatureMotion, feature_motion, keypoint_counts
from .colmap_masks import write_colmap_masks
from .config import PosesConfig
from .focal_check import check_model_focal
from .frame_list import check_name_order, read_frame_list, time_order
from .known_focal import known_focal
from .model_export import drop_frames, judge_camera_path, registered_poses, transforms_dict, write_model_outputs
from .quality_gate import (
    STATIC_ADVICE,
    blank_frames_note,
    check_motion,
    check_precheck,
    check_registration,
    check_trajectory,
    compact_names,
    feature_shortage,
    intrinsics_warnings,
    registration_advice,
    split_model_warning,
    too_few_frames_advice,
)
from .sfm import SfmResult, resolve_matcher, run_sfm
from .static_check import MotionPrecheck, measure_motion
from .up_check import check_model_up
from .world_frame import orient_reconstruction

STAGE_VERSION = "2"  # 2: the world frame is gravity- and wall-aligned (world_frame.py)
MIN_FRAMES = 3


def estimate_poses(cfg: PosesConfig) -> dict[str, Any]:
    """Run the stage; write ``cfg.out_dir`` atomically and return the content of poses.json.

    Raises StaticCameraError for a camera without baseline (from feature tracks before COLMAP runs, or from
    the model), DegenerateTrajectoryError for an implausible camera path, and PoseQualityError when fewer
    than ``cfg.min_registered`` of the frames get a pose; nothing is written then.
    """
    from stages.scene import InputError

    t_start = time.perf_counter()
    frames = read_frame_list(cfg.frames_dir)
    names = frames.names
    if len(names) < MIN_FRAMES:
        raise InputError(frames.image_dir, f"only {len(names)} frame(s); structure from motion needs at least "
                         f"{MIN_FRAMES} views with overlap", too_few_frames_advice(cfg.frames_dir))
    first = cv2.imread(str(frames.image_dir / names[0]), cv2.IMREAD_GRAYSCALE)
    if first is None:
        raise InputError(frames.image_dir / names[0], "image unreadable", "re-extract the frames")
    diagonal = float(np.hypot(*first.shape))
    focal = known_focal(cfg.focal_px, cfg.focal_35mm, cfg.refine_focal, first.shape[1], first.shape[0],
                        cfg.frames_dir)
    ordered, times = time_order(frames.names, frames.source_index)
    check_name_order(frames, ordered, resolve_matcher(cfg, len(names)))
    # a still camera is refused here in seconds, not after minutes of COLMAP (docs/poses.md, Quality gate)
    pre = measure_motion(frames.image_dir, ordered, cfg.static_motion_fraction, cfg.masks_dir)
    check_precheck(pre, ordered, cfg.frames_dir)
    warnings_: list[str] = []
    if pre.still_pair_fraction > cfg.max_still_share:
        warnings_.append(f"{pre.still_pair_fraction:.0%} of neighbouring sampled frames show no camera motion "
                         f"({', '.join(pre.still_spans[:6])}{', ...' if len(pre.still_spans) > 6 else ''}): a clip "
                         "filmed mostly from one spot is "
                         "refused after structure from motion")
        print(f"warning: {warnings_[-1]}", file=sys.stderr)  # now, so that a user can stop a long run
    motion_holder: dict[str, FeatureMotion] = {}
    keypoints: list[int] = []

    def after_matching(database: Path) -> None:
        motion_holder["motion"] = feature_motion(database)
        keypoints.extend(keypoint_counts(database))
        check_motion(motion_holder["motion"], diagonal, cfg.static_motion_fraction, cfg.frames_dir)

    with atomic_dir(cfg.out_dir, "poses", inputs=[cfg.frames_dir, cfg.masks_dir],
                    legacy=["poses.json"]) as out:
        work = out / "colmap_work"
        work.mkdir()
        mask_stats = None
        mask_dir = None
        timings: dict[str, float] = {"precheck": pre.seconds}
        if cfg.masks_dir is not None:
            t0 = time.perf_counter()
            mask_dir = work / "masks"
            mask_stats = write_colmap_masks(frames.image_dir, names, cfg.masks_dir, mask_dir, cfg.mask_dilate_px)
            timings["masks"] = time.perf_counter() - t0
        database = work / "database.db"
        sfm = run_sfm(cfg, database, frames.image_dir, names, mask_dir, work / "models", after_matching, focal)
        timings.update(sfm.timings)
        motion = motion_holder["motion"]
        rec = sfm.reconstruction
        registered = set(registered_poses(rec)) if rec is not None else set()
        detail, advice = registration_detail(rec, sfm, pre, cfg, keypoints,
                                             None if mask_stats is None else mask_stats.mean_excluded_fraction)
        detail += blank_frames_note(cfg.frames_dir, [n for n in ordered if n not in registered])
        # even with --min-registered 0 a model needs two posed frames to be a model at all
        min_fraction = max(cfg.min_registered, 2 / len(names))
        check_registration(names, registered, min_fraction, cfg.frames_dir, detail, advice)
        assert rec is not None  # the gate above rejects an empty result
        judged = judge_camera_path(rec, ordered, times, registered, sfm.model_sizes, cfg.trajectory_settings())
        warnings_ += check_trajectory(judged, cfg.frames_dir, cfg.trajectory_settings(),
                                      registration_advice(cfg, sfm.matcher), motion, pre)
        drop_frames(rec, judged.trimmed)
        registered -= set(judged.trimmed)
        if judged.trimmed:
            dropped = compact_names(judged.trimmed, order=ordered)
            detail += f" ({len(judged.trimmed)} frames dropped as jumps: {dropped})"
        fraction = check_registration(names, registered, min_fraction, cfg.frames_dir, detail, advice)
        left_out = [n for n in ordered if n not in registered and n not in judged.trimmed]
        if (split := split_model_warning(sfm.n_models, left_out, ordered, registration_advice(cfg, sfm.matcher))):
            warnings_.append(split)

        t0 = time.perf_counter()
        # a gravity- and wall-aligned world before anything is written, so every output shares it
        frame = orient_reconstruction(rec) if cfg.orient else None
        # a second, independent up (the largest horizontal plane of the points): warns, never turns the world
        up = check_model_up(rec) if frame is not None else None
        if up is not None and (up_warning := up.warning()) is not None:
            warnings_.append(up_warning)
        # does the motion determine the focal length? (a camera that does not turn leaves it free; warns only)
        focal_check = check_model_focal(rec, ordered, "estimated" if focal is None else
                                        "given, refined" if focal.refine else "given")
        if (focal_warning := focal_check.warning()) is not None:
            warnings_.append(focal_warning)
        # file_path relative to the final folder (not the atomic temp one): ns-train --data POSES resolves it
        transforms = transforms_dict(rec, frames.source_index, image_dir=frames.image_dir, out_dir=cfg.out_dir)
        if focal is not None:  # only then: a run without one writes what it always wrote
            transforms["focal_given"] = focal.as_dict()
            if (refined := focal.refined_warning(transforms["fl_x"])) is not None:
                warnings_.append(refined)
        warnings_ += intrinsics_warnings(transforms["fl_x"], transforms["fl_y"], transforms["w"], transforms["h"])
        write_model_outputs(out, rec, transforms, "livescene poses", None if frame is None else frame.as_dict())
        if cfg.keep_database:
            shutil.move(str(database), out / "database.db")
        shutil.rmtree(work)
        timings["export"] = time.perf_counter() - t0
        timings["total"] = time.perf_counter() - t_start
        summary = {
            "stage": "poses",
            "stage_version": STAGE_VERSION,
            "pycolmap_version": pycolmap.__version__,
            "frames_dir": str(cfg.frames_dir),
            "masks_dir": str(cfg.masks_dir) if cfg.masks_dir else None,
            "n_frames": len(names),
            "n_registered": len(registered),
            "registered_fraction": fraction,
            "registered": sorted(registered),
            "unregistered": [n for n in names if n not in registered and n not in judged.trimmed],
            "trimmed": judged.trimmed,
            "mean_reprojection_error": float(rec.compute_mean_reprojection_error()),
            "n_points3D": int(rec.num_points3D()),
            "mean_track_length": float(rec.compute_mean_track_length()),
            "n_models": sfm.n_models,
            "matcher": sfm.matcher,
            "camera": {"model": next(iter(rec.cameras.values())).model.name,
                       "params": [float(p) for p in next(iter(rec.cameras.values())).params],
                       **({} if focal is None else {"focal_given": focal.as_dict()})},
            "feature_motion": motion.as_dict(),
            "motion_precheck": pre.as_dict(),
            "trajectory": judged.as_dict(),
            "masks": None if mask_stats is None else {
                "frames_with_masks": mask_stats.frames_with_masks,
                "frames_without_masks": mask_stats.frames_without_masks,
                "mean_excluded_fraction": mask_stats.mean_excluded_fraction,
                "dilate_px": mask_stats.dilate_px,
            },
            "config": {"matcher": cfg.matcher, "threads": cfg.threads, "seed": cfg.seed,
                       "deterministic": cfg.deterministic,
                       "min_registered": cfg.min_registered, "camera_model": cfg.camera_model,
                       "max_image_size": cfg.max_image_size, "max_num_features": cfg.max_num_features,
                       "sequential_overlap": cfg.sequential_overlap,
                       "loop_detection": cfg.vocab_tree is not None, "orient": cfg.orient},
            "world_frame": None if frame is None else frame.as_dict(),
            **({} if up is None else {"up_check": up.as_dict()}),
            "focal_check": focal_check.as_dict(),
            "warnings": warnings_,
            "timings": timings,
        }
        write_json(out / "poses.json", summary)
    return summary


def registration_detail(rec: pycolmap.Reconstruction | None, sfm: SfmResult, pre: MotionPrecheck,
                        cfg: PosesConfig, keypoints: list[int] | None = None,
                        masked_fraction: float | None = None) -> tuple[str, str]:
    """What the registration error adds to its numbers, and the advice that fits what was tried.

    ``keypoints``: SIFT features kept per frame; ``masked_fraction``: the mean share of a frame the object
    masks hide (None without masks)."""
    detail = "" if rec is not None else " (COLMAP found no pair of frames to start a model from)"
    if sfm.n_models > 1:
        detail += f" (the sequence broke into {sfm.n_models} separate models; the largest is kept)"
    advice = registration_advice(cfg, sfm.matcher)
    shortage = feature_shortage(keypoints or [], masked_fraction)
    if shortage is not None:
        # too little to match in the frames themselves: matching harder or moving otherwise will not help first;
        # the pre-check's corners track as poorly then, so its "no parallax" is no evidence of a turn on the spot
        # (a 70-degree orbit of low-contrast frames showed none; docs/poses.md, Quality gate)
        detail += shortage[0]
        advice = shortage[1] + "; else " + advice
    elif pre.rotation_only_fraction == 1.0:
        # every moving pair fits a homography: a camera turning on the spot has nothing to triangulate
        detail += " (every sampled frame pair that moves shows no parallax: the camera turns on the spot)"
        advice = STATIC_ADVICE + "; else " + advice
    return detail, advice
