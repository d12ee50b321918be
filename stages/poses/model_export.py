"""Write a COLMAP model as nerfstudio transforms.json, a PLY point cloud and a scene box."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import open3d as o3d
import pycolmap

from stages.scene import Camera, atomic_path
from stages.scene.transforms import camera_to_dict

from .conventions import c2w_opengl_from_cam_from_world

# COLMAP parameter order per camera model -> (fx, fy, cx, cy, distortion keys in order)
_MODELS: dict[str, tuple[tuple[int, int, int, int], tuple[str, ...]]] = {
    "SIMPLE_PINHOLE": ((0, 0, 1, 2), ()),
    "PINHOLE": ((0, 1, 2, 3), ()),
    "SIMPLE_RADIAL": ((0, 0, 1, 2), ("k1",)),
    "RADIAL": ((0, 0, 1, 2), ("k1", "k2")),
    "OPENCV": ((0, 1, 2, 3), ("k1", "k2", "p1", "p2")),
}
SUPPORTED_CAMERA_MODELS = tuple(_MODELS)


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


def transforms_dict(reconstruction: pycolmap.Reconstruction, source_index: dict[str, int | None],
                    image_prefix: str = "images") -> dict[str, Any]:
    """nerfstudio-form transforms.json content: shared intrinsics, one frame per registered image."""
    cameras = list(reconstruction.cameras.values())
    if len(cameras) != 1:
        raise ValueError(f"expected one shared camera, the model has {len(cameras)}")
    out: dict[str, Any] = camera_to_dict(scene_camera(cameras[0]))
    frames = []
    for name, c2w in sorted(registered_poses(reconstruction).items()):
        image = reconstruction.find_image_with_name(name)
        frame: dict[str, Any] = {
            "file_path": f"{image_prefix}/{name}",
            "transform_matrix": c2w.tolist(),
            "colmap_im_id": int(image.image_id),
        }
        if source_index.get(name) is not None:
            frame["source_index"] = int(source_index[name])  # type: ignore[arg-type]
        frames.append(frame)
    out["frames"] = frames
    # nerfstudio reads this to undo any world change; none is applied (COLMAP world as is)
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


def scene_box(cloud: o3d.geometry.PointCloud, camera_centres: np.ndarray, nb_neighbors: int = 20,
              std_ratio: float = 2.0) -> tuple[np.ndarray, dict[str, Any]]:
    """Axis-aligned box around the points left after statistical outlier removal, grown to hold the cameras.

    Stray triangulations far outside the room would blow the box (and the
    model's sampling volume) up; open3d's statistical filter drops points
    whose mean neighbour distance is ``std_ratio`` deviations above average.
    The cameras are included because the model samples rays starting at them.
    """
    n = len(cloud.points)
    kept = cloud
    if n > nb_neighbors:
        kept, _ = cloud.remove_statistical_outlier(nb_neighbors=nb_neighbors, std_ratio=std_ratio)
    pts = np.asarray(kept.points)
    if len(camera_centres):
        pts = np.concatenate([pts, camera_centres]) if len(pts) else np.asarray(camera_centres)
    box = np.stack([pts.min(0), pts.max(0)])
    info = {"points_total": n, "points_kept": len(kept.points), "nb_neighbors": nb_neighbors,
            "std_ratio": std_ratio, "includes_camera_centres": bool(len(camera_centres))}
    return box, info
