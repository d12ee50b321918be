"""GLB exports stand upright in glTF viewers: the node turns the world's up axis to +y, positions stay put."""

from __future__ import annotations

import json
import struct

import numpy as np
import open3d as o3d
import pytest

from stages.export import read_glb, write_geometry
from stages.export.mesh_io import UP_TO_GLTF_Y
from stages.export.world_up import world_up_axis


def _quat_matrix(q: list[float]) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _glb_json(path) -> dict:
    data = path.read_bytes()
    length, _kind = struct.unpack_from("<II", data, 12)
    return json.loads(data[20:20 + length])


@pytest.mark.parametrize("up", sorted(UP_TO_GLTF_Y))
def test_the_node_turns_each_up_axis_to_gltf_y(up, tmp_path):
    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 3.0)
    write_geometry(tmp_path / "box.glb", mesh, up=up)
    node = _glb_json(tmp_path / "box.glb")["nodes"][0]
    axis = np.zeros(3)
    axis["xyz".index(up[1])] = 1.0 if up[0] == "+" else -1.0
    turn = _quat_matrix(node["rotation"]) if "rotation" in node else np.eye(3)
    np.testing.assert_allclose(turn @ axis, [0.0, 1.0, 0.0], atol=1e-12)
    assert np.linalg.det(turn) == pytest.approx(1.0)
    np.testing.assert_allclose(read_glb(tmp_path / "box.glb")["positions"], np.asarray(mesh.vertices))
    with pytest.raises(ValueError, match="up axis"):
        write_geometry(tmp_path / "bad.glb", mesh, up="up")


def _camera(up: np.ndarray, tilt_deg: float) -> np.ndarray:
    """An OpenGL camera-to-world whose up vector leans ``tilt_deg`` from ``up``."""
    up = up / np.linalg.norm(up)
    side = np.cross(up, [0.3, 0.5, 0.7])
    side /= np.linalg.norm(side)
    t = np.radians(tilt_deg)
    cam_up = np.cos(t) * up + np.sin(t) * side
    back = np.cross(side, cam_up)
    right = np.cross(cam_up, back)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2] = right, cam_up, back
    return c2w


def test_world_up_is_the_axis_nearest_the_cameras_up():
    assert world_up_axis([_camera(np.array([0.0, 0.0, 1.0]), t) for t in (10, 25, -20)]) == "+z"
    assert world_up_axis([_camera(np.array([0.0, -1.0, 0.0]), 30)]) == "-y"
    assert world_up_axis([_camera(np.array([1.0, 0.2, 0.1]), 5)]) == "+x"
    assert world_up_axis([]) == "+y"


def test_cameras_whose_up_vectors_cancel_fall_back_to_gltf_up():
    upright = _camera(np.array([0.0, 0.0, 1.0]), 0)
    upside_down = upright.copy()
    upside_down[:3, :2] *= -1  # rolled by 180 degrees: its up is -z
    assert world_up_axis([upright, upside_down]) == "+y"  # no direction to choose: glTF's own, no rotation
