"""The pose stage end to end: frames (+ masks) -> COLMAP model, transforms.json, point cloud, scene box."""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pycolmap

from stages.scene import atomic_dir, write_json

from .camera_motion import FeatureMotion, feature_motion, model_baseline
from .colmap_masks import write_colmap_masks
from .config import PosesConfig
from .frame_list import read_frame_list
from .model_export import point_cloud, registered_poses, scene_box, transforms_dict, write_ply
from .quality_gate import check_baseline, check_motion, check_registration, intrinsics_warnings
from .sfm import run_sfm

STAGE_VERSION = "1"
MIN_FRAMES = 3


def estimate_poses(cfg: PosesConfig) -> dict[str, Any]:
    """Run the stage; write ``cfg.out_dir`` atomically and return the content of poses.json.

    Raises StaticCameraError for a camera without baseline and
    PoseQualityError when fewer than ``cfg.min_registered`` of the frames
    get a pose; nothing is written then.
    """
    from stages.scene import InputError

    t_start = time.perf_counter()
    frames = read_frame_list(cfg.frames_dir)
    names = frames.names
    if len(names) < MIN_FRAMES:
        raise InputError(frames.image_dir, f"only {len(names)} frame(s); structure from motion needs at least "
                         f"{MIN_FRAMES} views with overlap", "extract more frames (`livescene frames --stride 1`)")
    first = cv2.imread(str(frames.image_dir / names[0]), cv2.IMREAD_GRAYSCALE)
    if first is None:
        raise InputError(frames.image_dir / names[0], "image unreadable", "re-extract the frames")
    diagonal = float(np.hypot(*first.shape))
    motion_holder: dict[str, FeatureMotion] = {}

    def after_matching(database: Path) -> None:
        motion_holder["motion"] = feature_motion(database)
        check_motion(motion_holder["motion"], diagonal, cfg.static_motion_fraction, cfg.frames_dir)

    with atomic_dir(cfg.out_dir) as out:
        work = out / "colmap_work"
        work.mkdir()
        mask_stats = None
        mask_dir = None
        timings: dict[str, float] = {}
        if cfg.masks_dir is not None:
            t0 = time.perf_counter()
            mask_dir = work / "masks"
            mask_stats = write_colmap_masks(frames.image_dir, names, cfg.masks_dir, mask_dir, cfg.mask_dilate_px)
            timings["masks"] = time.perf_counter() - t0
        database = work / "database.db"
        sfm = run_sfm(cfg, database, frames.image_dir, names, mask_dir, work / "models", after_matching)
        timings.update(sfm.timings)
        motion = motion_holder["motion"]
        rec = sfm.reconstruction
        registered = set(registered_poses(rec)) if rec is not None else set()
        if rec is not None and len(registered) >= 2:
            check_baseline(model_baseline(rec), motion, cfg.frames_dir)
        detail = "" if rec is not None else " (COLMAP found no pair of frames to start a model from)"
        if sfm.n_models > 1:
            detail += f" (the sequence broke into {sfm.n_models} separate models; the largest is kept)"
        # even with --min-registered 0 a model needs two posed frames to be a model at all
        fraction = check_registration(names, registered, max(cfg.min_registered, 2 / len(names)), cfg.frames_dir,
                                      detail)
        assert rec is not None  # the gate above rejects an empty result

        t0 = time.perf_counter()
        sparse = out / "sparse" / "0"
        sparse.mkdir(parents=True)
        rec.write(output_dir=sparse)
        transforms = transforms_dict(rec, frames.source_index)
        warnings_ = intrinsics_warnings(transforms["fl_x"], transforms["fl_y"], transforms["w"], transforms["h"])
        write_json(out / "transforms.json", transforms)
        cloud = point_cloud(rec)
        write_ply(cloud, out / "points3D.ply")
        centres = np.array([f["transform_matrix"] for f in transforms["frames"]])[:, :3, 3]
        box, box_info = scene_box(cloud, centres)
        write_json(out / "scene.json", {"scene_box": box.tolist(), "units": "colmap",
                                        "scene_box_rule": "open3d statistical outlier removal on points3D, "
                                                          "grown to include the camera centres",
                                        **box_info, "source": "livescene poses"})
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
            "unregistered": [n for n in names if n not in registered],
            "mean_reprojection_error": float(rec.compute_mean_reprojection_error()),
            "n_points3D": int(rec.num_points3D()),
            "mean_track_length": float(rec.compute_mean_track_length()),
            "n_models": sfm.n_models,
            "matcher": sfm.matcher,
            "camera": {"model": next(iter(rec.cameras.values())).model.name,
                       "params": [float(p) for p in next(iter(rec.cameras.values())).params]},
            "feature_motion": motion.as_dict(),
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
                       "loop_detection": cfg.vocab_tree is not None},
            "warnings": warnings_,
            "timings": timings,
        }
        write_json(out / "poses.json", summary)
    return summary
