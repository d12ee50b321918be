"""The bytes of the written formats: colour encodings, PLY normals and colours, OBJ colours, GLB accessors."""

from __future__ import annotations

import json
import struct

import numpy as np
import open3d as o3d
import pytest

from stages.export import read_glb, write_geometry
from stages.export.mesh_io import srgb_to_linear


def _box() -> o3d.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh.create_box(1.0, 2.0, 3.0)
    mesh.compute_vertex_normals()
    mesh.vertex_colors = o3d.utility.Vector3dVector(np.full((8, 3), 0.5))
    return mesh


def test_srgb_to_linear_follows_iec_61966_2_1_on_both_branches():
    dark, mid = 0.02, 0.5
    assert srgb_to_linear(np.array([dark]))[0] == pytest.approx(0.02 / 12.92, rel=1e-12)  # linear toe
    assert srgb_to_linear(np.array([mid]))[0] == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4, rel=1e-12)
    assert srgb_to_linear(np.array([0.0, 1.0])).tolist() == [0.0, 1.0]


def test_ply_stores_rounded_colours_and_the_normals(tmp_path):
    mesh = _box()
    write_geometry(tmp_path / "box.ply", mesh)
    back = o3d.io.read_triangle_mesh(str(tmp_path / "box.ply"))
    assert np.allclose(np.asarray(back.vertex_colors), 128 / 255)  # 0.5 * 255 = 127.5, rounded to 128
    assert back.has_vertex_normals()
    assert np.allclose(np.asarray(back.vertex_normals), np.asarray(mesh.vertex_normals), atol=1e-6)
    header = (tmp_path / "box.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property float nx" in header and "property uchar red" in header


def test_obj_vertices_carry_their_colours_and_faces_count_from_one(tmp_path):
    mesh = _box()
    write_geometry(tmp_path / "box.obj", mesh)
    lines = (tmp_path / "box.obj").read_text().splitlines()
    v = [line.split()[1:] for line in lines if line.startswith("v ")]
    assert len(v) == 8 and all(len(row) == 6 for row in v) and all(row[3:] == ["0.5"] * 3 for row in v)
    faces = [line.split()[1:] for line in lines if line.startswith("f ")]
    indices = np.array([[int(c.split("//")[0]) for c in f] for f in faces])
    assert indices.min() == 1 and indices.max() == 8  # OBJ counts vertices from 1
    assert np.array_equal(indices - 1, np.asarray(mesh.triangles))


def _glb(path) -> tuple[dict, int, int]:
    data = path.read_bytes()
    length, _kind = struct.unpack_from("<II", data, 12)
    return json.loads(data[20 : 20 + length]), length, len(data)


def test_glb_accessors_declare_bounds_and_chunks_are_aligned(tmp_path):
    """glTF requires POSITION's min/max; the index accessor's max is the largest index (open3d wrote the count
    minus one); chunks are 4-byte aligned."""
    mesh = _box()
    write_geometry(tmp_path / "box.glb", mesh)
    doc, json_length, total = _glb(tmp_path / "box.glb")
    assert json_length % 4 == 0 and total % 4 == 0
    prim = doc["meshes"][0]["primitives"][0]
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    assert pos["min"] == [0.0, 0.0, 0.0] and pos["max"] == [1.0, 2.0, 3.0]
    idx = doc["accessors"][prim["indices"]]
    assert idx["count"] == 36 and idx["min"] == [0] and idx["max"] == [7]
    assert "NORMAL" in prim["attributes"]
    assert len(read_glb(tmp_path / "box.glb")["triangles"]) == 12


def test_the_json_chunk_is_padded_to_four_bytes_whatever_its_length(tmp_path):
    lengths = set()
    for n in range(1, 5):  # clouds of 1..4 points: JSON chunks of different lengths
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.arange(3 * n, dtype=float).reshape(n, 3)))
        write_geometry(tmp_path / f"{n}.glb", cloud)
        data = (tmp_path / f"{n}.glb").read_bytes()
        length = struct.unpack_from("<I", data, 12)[0]
        assert length % 4 == 0 and len(data) % 4 == 0
        assert data[20 : 20 + length].decode().rstrip(" ").endswith("}")  # padded with spaces, as glTF requires
        lengths.add(len(data[20 : 20 + length].decode().rstrip(" ")))
    assert len({n % 4 for n in lengths}) > 1  # some of them needed padding
