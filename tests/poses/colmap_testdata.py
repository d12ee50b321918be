"""COLMAP models written with pycolmap from known poses, as a COLMAP made elsewhere would leave them.

No structure from motion runs: the cameras sit where ``orbit_poses`` puts them, the points are random
points of the room seen by at least two cameras, and every keypoint is the exact projection of its
point (reprojection error 0), so an import can be checked number for number.
"""

from __future__ import annotations

from pathlib import Path

import cv2  # noqa: F401  (must load before pycolmap: the reverse order crashes cv2's PNG writer)
import numpy as np
import pycolmap
from poses_testdata import ROOM_MAX, ROOM_MIN, SMALL_CAMERA, orbit_poses

from stages.poses import cam_from_world_from_c2w_opengl
from stages.scene import Camera

RADIAL_K = (0.02, -0.01)
OPENCV_K = (-0.04, 0.01, 0.002, -0.003)
"""k1, k2, p1, p2 of the OPENCV model's camera."""


def colmap_camera(camera: Camera, model: str = "RADIAL", camera_id: int = 1) -> pycolmap.Camera:
    cam = pycolmap.Camera.create_from_model_name(camera_id, model, camera.fx, camera.width, camera.height)
    params = {"SIMPLE_PINHOLE": [camera.fx, camera.cx, camera.cy],
              "PINHOLE": [camera.fx, camera.fy, camera.cx, camera.cy],
              "RADIAL": [camera.fx, camera.cx, camera.cy, *RADIAL_K],
              "OPENCV": [camera.fx, camera.fy, camera.cx, camera.cy, *OPENCV_K],
              "OPENCV_FISHEYE": [camera.fx, camera.fy, camera.cx, camera.cy, 0.01, 0.0, 0.0, 0.0]}[model]
    cam.params = params
    return cam


def synthetic_model(names: list[str], poses: list[np.ndarray], camera: Camera = SMALL_CAMERA, model: str = "RADIAL",
                    n_points: int = 400, seed: int = 0, second_camera: Camera | None = None) -> pycolmap.Reconstruction:
    """A model whose image ``names[k]`` has the OpenGL camera-to-world pose ``poses[k]``.

    ``second_camera``: odd images use this one (camera id 2), as COLMAP's per-folder camera mode would.
    """
    rng = np.random.default_rng(seed)
    rec = pycolmap.Reconstruction()
    cams = [colmap_camera(camera, model)]
    if second_camera is not None:
        cams.append(colmap_camera(second_camera, model, camera_id=2))
    for cam in cams:
        rec.add_camera_with_trivial_rig(cam)
    xyz = rng.uniform(ROOM_MIN + 0.1, ROOM_MAX - 0.1, (n_points, 3))
    observations: list[list[tuple[int, int]]] = [[] for _ in range(n_points)]
    for k, (name, c2w) in enumerate(zip(names, poses, strict=True)):
        rotation, translation = cam_from_world_from_c2w_opengl(c2w)
        cam = cams[k % len(cams)]
        in_cam = xyz @ rotation.T + translation
        front = np.where(in_cam[:, 2] > 0.1)[0]
        uv = np.asarray(cam.img_from_cam(in_cam[front]))
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] < camera.height)
        seen, uv = front[inside], uv[inside]
        image = pycolmap.Image(name=name, keypoints=uv, camera_id=cam.camera_id, image_id=k + 1)
        pose = pycolmap.Rigid3d(rotation=pycolmap.Rotation3d(rotation), translation=translation)
        rec.add_image_with_trivial_frame(image, pose)
        for j, p in enumerate(seen):
            observations[p].append((k + 1, j))
    for p, obs in enumerate(observations):
        if len(obs) >= 2:
            track = pycolmap.Track([pycolmap.TrackElement(image_id=i, point2D_idx=j) for i, j in obs])
            point_id = rec.add_point3D(xyz[p], track, np.array([200, 100, 50], np.uint8))
            for i, j in obs:
                rec.image(i).set_point3D_for_point2D(j, point_id)
    rec.update_point_3d_errors()
    return rec


def write_model(rec: pycolmap.Reconstruction, folder: Path, binary: bool = True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    if binary:
        rec.write_binary(folder)
    else:
        rec.write_text(folder)
    return folder


def default_scene(n: int = 12) -> tuple[list[int], list[np.ndarray]]:
    """Frame numbers 1..n (image folders number from 1) and their poses."""
    return list(range(1, n + 1)), orbit_poses(n)
