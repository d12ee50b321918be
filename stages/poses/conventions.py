"""Pose conventions: COLMAP (world-to-camera, OpenCV axes, quaternion) <-> nerfstudio (camera-to-world, OpenGL).

COLMAP stores for each image the rigid transform ``cam_from_world`` with
camera axes x right, y down, z forward, its rotation as a unit quaternion
(``qw qx qy qz`` in images.txt; pycolmap's ``Rotation3d.quat`` is ``[x, y, z, w]``).
nerfstudio's ``transform_matrix`` is the inverse (camera to world) with the
camera looking down -z and +y up, so the y and z camera axes flip. These conversions leave the
world frame as it is; transforms.json, points3D.ply and sparse/0 share one
world (COLMAP's, turned upright by world_frame.py unless --no-orient).
"""

from __future__ import annotations

import itertools

import numpy as np

from stages.scene import opencv_to_opengl, opengl_to_opencv


def c2w_opengl_from_cam_from_world(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """4x4 OpenGL camera-to-world from COLMAP's world-to-camera rotation (3x3) and translation (3,)."""
    w2c = np.eye(4)
    w2c[:3, :3] = np.asarray(rotation, dtype=np.float64)
    w2c[:3, 3] = np.asarray(translation, dtype=np.float64)
    return opencv_to_opengl(np.linalg.inv(w2c))


def cam_from_world_from_c2w_opengl(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's world-to-camera (rotation 3x3, translation 3) from an OpenGL camera-to-world matrix."""
    w2c = np.linalg.inv(opengl_to_opencv(np.asarray(c2w, dtype=np.float64)))
    return w2c[:3, :3], w2c[:3, 3]


def quaternion_wxyz_from_rotation(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion ``[w, x, y, z]`` (COLMAP's images.txt order), w >= 0."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(rotation, dtype=np.float64)).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def rotation_from_quaternion_wxyz(q: np.ndarray) -> np.ndarray:
    """3x3 rotation from a ``[w, x, y, z]`` quaternion (normalised first)."""
    from scipy.spatial.transform import Rotation

    w, x, y, z = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def rotation_angle_deg(r_a: np.ndarray, r_b: np.ndarray) -> float:
    """Geodesic angle between two rotations, in degrees.

    Taken from the rotation vector of ``r_a^T r_b`` rather than ``arccos`` of the trace, which loses
    precision for the small angles a pose error report is about.
    """
    from scipy.spatial.transform import Rotation

    return float(np.degrees(Rotation.from_matrix(np.asarray(r_a).T @ np.asarray(r_b)).magnitude()))


def axis_misalignment_deg(rotation: np.ndarray) -> float:
    """Degrees between ``rotation`` and the nearest proper signed permutation of the axes.

    0 when two worlds share their axes up to relabelling and sign (all an axis-aligned factorisation cares
    about); used to judge the poses stage's upright world against a reference (docs/poses.md, "World frame").
    """
    best = 180.0
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1.0, -1.0), repeat=3):
            p = np.zeros((3, 3))
            p[range(3), perm] = signs
            if np.linalg.det(p) > 0:
                best = min(best, rotation_angle_deg(p, rotation))
    return best
