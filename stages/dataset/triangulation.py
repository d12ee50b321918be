"""Sparse points of a ready dataset from its own images at their given poses (COLMAP's point triangulator).

``dataset orient`` needs a point cloud to find the floor and the walls. A dataset that came without one
(no ``ply_file_path``) gets it here, as COLMAP builds a model from known poses: SIFT on every image, matching
as the poses stage matches (exhaustive for a few images, sequential in name order for more), then
``pycolmap.triangulate_points`` with the cameras fixed at the dataset's intrinsics and poses. Nothing is
refined: the points are only read for their normals and box. Single-threaded and seeded, as the poses stage
runs COLMAP by default, so the same dataset gives the same points (docs/poses.md, "Ready datasets").
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import open3d as o3d
import pycolmap

from stages.poses import PosesConfig, cam_from_world_from_c2w_opengl
from stages.poses.sfm import colmap_log_level, match_features, resolve_matcher
from stages.scene import Camera, SceneDataset, SceneError
from stages.scene.atomic_io import scratch_folder

from .assemble import place_image


def _colmap_model(cameras: list[Camera]) -> str:
    """COLMAP's model for the dataset's cameras: OPENCV (fx, fy, cx, cy, k1, k2, p1, p2), or FULL_OPENCV where a camera
    has k3, whose radial factor ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 + k6 r^6)`` is OpenCV's
    polynomial with its denominator's k4..k6 at 0 (COLMAP's k4 is not nerfstudio's r^8 term)."""
    return "FULL_OPENCV" if any(c.distortion.get("k3", 0.0) for c in cameras) else "OPENCV"


def _colmap_params(camera: Camera, model: str = "OPENCV") -> list[float]:
    """``camera``'s parameters in ``model``'s order (``_colmap_model``)."""
    d = camera.distortion
    params = [camera.fx, camera.fy, camera.cx, camera.cy, *(float(d.get(k, 0.0)) for k in ("k1", "k2", "p1", "p2"))]
    return [*params, float(d.get("k3", 0.0)), 0.0, 0.0, 0.0] if model == "FULL_OPENCV" else params


def triangulate_dataset(ds: SceneDataset, seed: int = 0) -> o3d.geometry.PointCloud:
    """Points of the scene triangulated from ``ds``'s images at their given poses (see the module docstring)."""
    names = [Path(f.file_path).name for f in ds.frames]
    if len(set(names)) != len(names):
        raise SceneError(ds.root / "transforms.json", "two frames' images share a file name",
                         "give the images distinct file names, or pass --points")
    by_name = dict(zip(names, ds.frames, strict=True))
    with scratch_folder("livescene-triangulate-") as tmp:
        work = Path(tmp)
        images = work / "images"
        images.mkdir()
        for name, frame in by_name.items():
            place_image(ds.image_path(frame), images / name, copy=False)
        cfg = PosesConfig(frames_dir=images, out_dir=work / "unused", seed=seed)
        database = work / "database.db"
        per_image = any(f.camera is not None for f in ds.frames)
        cameras = [ds.camera_of(f) for f in ds.frames]
        model_name = _colmap_model(cameras)
        if any(c.distortion.get("k4", 0.0) for c in cameras):  # nerfstudio's r^8 term: no COLMAP model has it
            warnings.warn(f"{ds.root / 'transforms.json'}: COLMAP has no model with the r^8 coefficient k4; the "
                          "points the orientation reads (for the floor's and walls' normals only) are triangulated "
                          "without it; fix: pass --points to give a point cloud", stacklevel=2)
        with colmap_log_level(False):
            pycolmap.set_random_seed(seed=seed)
            extraction = pycolmap.FeatureExtractionOptions(num_threads=1, max_image_size=cfg.max_image_size,
                                                           use_gpu=False)
            extraction.sift.max_num_features = cfg.max_num_features
            pycolmap.extract_features(database_path=database, image_path=images, image_names=names,
                                      camera_mode=pycolmap.CameraMode.PER_IMAGE if per_image
                                      else pycolmap.CameraMode.SINGLE,
                                      reader_options=pycolmap.ImageReaderOptions(camera_model=model_name),
                                      extraction_options=extraction, device=pycolmap.Device.cpu)
            match_features(cfg, database, resolve_matcher(cfg, len(names)))
            db = pycolmap.Database.open(str(database))
            try:
                model = pycolmap.Reconstruction()
                stored = db.read_all_images()
                camera_of = {im.camera_id: ds.camera_of(by_name[im.name]) for im in stored}
                for cam in db.read_all_cameras():
                    cam.params = _colmap_params(camera_of[cam.camera_id], model_name)
                    model.add_camera_with_trivial_rig(cam)
                for im in stored:
                    rotation, translation = cam_from_world_from_c2w_opengl(np.asarray(by_name[im.name].c2w))
                    keypoints = db.read_keypoints(im.image_id)[:, :2]
                    image = pycolmap.Image(name=im.name, keypoints=keypoints, camera_id=im.camera_id,
                                           image_id=im.image_id)
                    model.add_image_with_trivial_frame(image, pycolmap.Rigid3d(
                        rotation=pycolmap.Rotation3d(rotation), translation=translation))
            finally:
                db.close()
            (work / "model").mkdir()
            pycolmap.triangulate_points(model, database, images, work / "model")
        xyz = np.array([p.xyz for p in model.points3D.values()], dtype=np.float64).reshape(-1, 3)
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))

