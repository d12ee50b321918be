"""Write a COLMAP model as nerfstudio transforms.json, a PLY point cloud and a scene box.

Shared by ``livescene poses`` (a model it estimated) and ``livescene poses import`` (a model made
elsewhere), so both write the same POSES folder (docs/data-contract.md).
"""

from __future__ import annotations

import os
from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import open3d as o3d
import pycolmap

from stages.scene import Camera, atomic_path, write_json
from stages.scene.transforms import camera_to_dict

from .conventions import c2w_opengl_from_cam_from_world
from .trajectory_check import TrajectoryJudgement, TrajectorySettings, judge_trajectory, median_point_depth

# COLMAP parameter order per camera model -> (fx, fy, cx, cy, distortion keys in order)
_MODELS: dict[str, tuple[tuple[int, int, int, int], tuple[str, ...]]] = {
    "SIMPLE_PINHOLE": ((0, 0, 1, 2), ()),
    "PINHOLE": ((0, 1, 2, 3), ()),
    "SIMPLE_RADIAL": ((0, 0, 1, 2), ("k1",)),
    "RADIAL": ((0, 0, 1, 2), ("k1", "k2")),
    "OPENCV": ((0, 1, 2, 3), ("k1", "k2", "p1", "p2")),
}
SUPPORTED_CAMERA_MODELS = tuple(_MODELS)
"""The COLMAP models whose projection the contract's Camera reproduces exactly: pinhole plus OpenCV
radial-tangential distortion. Fisheye and other models bend rays differently (docs/poses.md)."""


def scene_camera(camera: pycolmap.Camera) -> Camera:
    """The contract's Camera from a COLMAP camera (both put pixel centres at +0.5)."""
    name = camera.model.name
    if name not in _MODELS:
        raise ValueError(f"camera model {name} is not supported; use one of {SUPPORTED_CAMERA_MODELS}")
    (ix, iy, icx, icy), dist_keys = _MODELS[name]
    p = np.asarray(camera.params, dtype=np.float64)
    first_dist = 4 if ix != iy else 3
    distortion = {k: float(p[first_dist + j]) for j, k in enumerate(dist_keys) if float(p[first_dist + j]) != 0.0}
    return Camera(fx=float(p[ix]), fy=float(p[iy]), cx=float(p[icx]), cy=float(p[icy]),
                  width=int(camera.width), height=int(camera.height), distortion=distortion)


def registered_poses(reconstruction: pycolmap.Reconstruction) -> dict[str, np.ndarray]:
    """Image name -> 4x4 OpenGL camera-to-world, for every image with a pose."""
    out = {}
    for image in reconstruction.images.values():
        if image.has_pose:
            pose = image.cam_from_world()
            out[image.name] = c2w_opengl_from_cam_from_world(pose.rotation.matrix(), pose.translation)
    return out


def drop_frames(rec: pycolmap.Reconstruction, names: list[str]) -> None:
    """Deregister the images ``names`` (trimmed by the trajectory gate): sparse/0 and transforms.json then agree."""
    for name in names:
        rec.deregister_frame(rec.find_image_with_name(name).frame_id)


def judge_camera_path(rec: pycolmap.Reconstruction, ordered: list[str], times: dict[str, float],
                      registered: Collection[str], model_sizes: list[int], settings: TrajectorySettings
                      ) -> TrajectoryJudgement:
    """The trajectory gate's numbers for the ``registered`` cameras of ``rec``, in the playback order ``ordered``
    of all the frames (``time_order``); the structure-from-motion run and the import judge alike."""
    order = [n for n in ordered if n in registered]
    centres = np.array([rec.find_image_with_name(n).projection_center() for n in order]).reshape(-1, 3)
    points = np.array([p.xyz for p in rec.points3D.values()], dtype=np.float64).reshape(-1, 3)
    return judge_trajectory(order, centres, np.array([times[n] for n in order]), median_point_depth(centres, points),
                            len(ordered), model_sizes, settings)


def relative_file_path(image: Path, out_dir: Path) -> str:
    """``file_path`` of ``image`` relative to the folder transforms.json is written to.

    nerfstudio resolves ``file_path`` as ``<folder of transforms.json> / file_path`` (so does
    ``stages.scene.transforms.resolve_image_path``): a POSES folder next to a FRAMES folder names
    ``../frames/images/frame_00001.png``, and ``ns-train --data POSES`` finds the images.
    ``out_dir`` need not exist yet (outputs are written into a temporary sibling first).
    """
    image = Path(os.path.abspath(image))
    out_dir = Path(os.path.abspath(out_dir))
    return Path(os.path.relpath(image, out_dir)).as_posix()


def transforms_dict(reconstruction: pycolmap.Reconstruction, source_index: Mapping[str, int | None],
                    image_prefix: str = "images", *, image_dir: Path | None = None, out_dir: Path | None = None,
                    file_paths: Mapping[str, str] | None = None) -> dict[str, Any]:
    """nerfstudio-form transforms.json content: intrinsics, one frame per registered image.

    ``file_path`` of a frame: ``file_paths[name]`` when given (images not in it are left out), else
    the image in ``image_dir`` relative to ``out_dir`` when both are given (see
    ``relative_file_path``), else ``image_prefix/name``. One camera gives shared intrinsics at the
    top level; several give per-frame intrinsics (nerfstudio reads a key per frame when the top
    level lacks it).
    """
    cameras = {cid: scene_camera(cam) for cid, cam in reconstruction.cameras.items()}
    posed = sorted(registered_poses(reconstruction).items())
    if file_paths is not None:
        posed = [(name, c2w) for name, c2w in posed if name in file_paths]
    images = {name: reconstruction.find_image_with_name(name) for name, _ in posed}
    used = sorted({images[name].camera_id for name, _ in posed}) or sorted(cameras)
    shared = cameras[used[0]] if len(used) == 1 else None
    out: dict[str, Any] = camera_to_dict(shared) if shared is not None else {
        "camera_model": "OPENCV" if any(cameras[c].has_distortion for c in used) else "PINHOLE"}
    frames = []
    for name, c2w in posed:
        image = images[name]
        if file_paths is not None:
            path = file_paths[name]
        elif image_dir is not None and out_dir is not None:
            path = relative_file_path(Path(image_dir) / name, Path(out_dir))
        else:
            path = f"{image_prefix}/{name}"
        frame: dict[str, Any] = {"file_path": path, "transform_matrix": c2w.tolist(),
                                 "colmap_im_id": int(image.image_id)}
        if shared is None:
            intrinsics = camera_to_dict(cameras[image.camera_id])
            intrinsics.pop("camera_model")  # nerfstudio reads the model from the top level only
            frame.update(intrinsics)
        if source_index.get(name) is not None:
            frame["source_index"] = int(source_index[name])  # type: ignore[arg-type]
        frames.append(frame)
    out["frames"] = frames
    # nerfstudio reads this to undo a world change made after the COLMAP model; the upright turn
    # (world_frame.py) is applied to sparse/0 as well, so the model and this file agree: identity
    out["applied_transform"] = np.eye(4)[:3].tolist()
    out["ply_file_path"] = "points3D.ply"
    return out


def point_cloud(reconstruction: pycolmap.Reconstruction) -> o3d.geometry.PointCloud:
    points = reconstruction.points3D.values()
    xyz = np.array([p.xyz for p in points], dtype=np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in points], dtype=np.float64).reshape(-1, 3) / 255.0
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
    cloud.colors = o3d.utility.Vector3dVector(rgb)
    return cloud


def write_ply(cloud: o3d.geometry.PointCloud, path: Path) -> None:
    with atomic_path(path, suffix=".ply") as tmp:
        if not o3d.io.write_point_cloud(str(tmp), cloud, write_ascii=False):
            raise OSError(f"open3d could not write {path}")


def inlier_points(cloud: o3d.geometry.PointCloud, nb_neighbors: int = 20, std_ratio: float = 2.0
                  ) -> o3d.geometry.PointCloud:
    """The points open3d's statistical filter keeps: those whose mean neighbour distance is at most ``std_ratio``
    deviations above average (stray triangulations far outside the room go)."""
    if len(cloud.points) <= nb_neighbors:
        return cloud
    kept, _ = cloud.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    return kept


def scene_box(cloud: o3d.geometry.PointCloud, camera_centres: np.ndarray, nb_neighbors: int = 20,
              std_ratio: float = 2.0) -> tuple[np.ndarray, dict[str, Any]]:
    """Axis-aligned box around the points left after statistical outlier removal, grown to hold the cameras.

    Stray triangulations far outside the room would blow the box (and the model's sampling volume) up
    (``inlier_points``). The cameras are included because the model samples rays starting at them.
    """
    n = len(cloud.points)
    kept = inlier_points(cloud, nb_neighbors, std_ratio)
    pts = np.asarray(kept.points)
    if len(camera_centres):
        pts = np.concatenate([pts, camera_centres]) if len(pts) else np.asarray(camera_centres)
    box = np.stack([pts.min(0), pts.max(0)])
    info = {"points_total": n, "points_kept": len(kept.points), "nb_neighbors": nb_neighbors,
            "std_ratio": std_ratio, "includes_camera_centres": bool(len(camera_centres))}
    return box, info


def write_model_outputs(out: Path, reconstruction: pycolmap.Reconstruction, transforms: dict[str, Any],
                        source: str, world_frame: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write sparse/0, transforms.json, points3D.ply and scene.json into ``out``; return scene.json.

    ``transforms`` is ``transforms_dict``'s result for this model; the scene box holds the points
    (outliers removed) and the camera centres of its frames.
    """
    sparse = out / "sparse" / "0"
    sparse.mkdir(parents=True, exist_ok=True)
    reconstruction.write(output_dir=sparse)
    write_json(out / "transforms.json", transforms)
    cloud = point_cloud(reconstruction)
    write_ply(cloud, out / "points3D.ply")
    centres = np.array([f["transform_matrix"] for f in transforms["frames"]]).reshape(-1, 4, 4)[:, :3, 3]
    box, box_info = scene_box(cloud, centres)
    scene = {"scene_box": box.tolist(), "units": "colmap",
             "scene_box_rule": "open3d statistical outlier removal on points3D, grown to include the camera centres",
             **box_info, "source": source}
    if world_frame is not None:
        scene["world_frame"] = world_frame
    write_json(out / "scene.json", scene)
    return scene
