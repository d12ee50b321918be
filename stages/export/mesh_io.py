"""Write meshes and point clouds as PLY, OBJ or GLB, atomically (docs/export.md, "Formats").

All three are written here with numpy (open3d's writers refuse an empty mesh, and an object
that no view showed at some state exports as an empty file rather than none). open3d 0.20's
``write_triangle_mesh`` does write a ``.glb``, but it embeds the buffer as a base64 data URI (a
third larger), declares the index accessor's max as the index COUNT minus one, and open3d's own
reader (assimp) cannot read the file back. The GLB writer below follows the glTF 2.0 binary
layout: one JSON chunk, one BIN chunk, uint32 indices, float32 positions (with the required min/max) and normals, and
normalised uint8 RGBA vertex colours. Coordinates stay in the dataset's world in every format, so
the parts of one export and the exports of different states line up. glTF's up is +y; a GLB's node
carries the rotation that takes the world's up axis there (``up``), leaving the stored positions alone.
"""

from __future__ import annotations

import base64
import io
import json
import struct
from pathlib import Path

import numpy as np
import open3d as o3d

from stages.scene import atomic_path

FORMATS = ("ply", "obj", "glb")
_GLB_MAGIC, _CHUNK_JSON, _CHUNK_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_FLOAT, _UINT, _UBYTE = 5126, 5125, 5121
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_POINTS, _TRIANGLES = 0, 4
_H = float(np.sqrt(0.5))
UP_TO_GLTF_Y = {"+y": None, "-y": [1.0, 0.0, 0.0, 0.0], "+z": [-_H, 0.0, 0.0, _H], "-z": [_H, 0.0, 0.0, _H],
                "+x": [0.0, 0.0, _H, _H], "-x": [0.0, 0.0, -_H, _H]}
"""Node rotation (unit quaternion x, y, z, w) turning a world whose up is the named axis to glTF's +y up."""


def mesh_arrays(mesh: o3d.geometry.TriangleMesh) -> dict[str, np.ndarray]:
    """Vertices float32 [N, 3], triangles uint32 [M, 3], normals and colours float32 [N, 3] (may be empty)."""
    return {"positions": np.asarray(mesh.vertices, dtype=np.float32).reshape(-1, 3),
            "triangles": np.asarray(mesh.triangles, dtype=np.uint32).reshape(-1, 3),
            "normals": np.asarray(mesh.vertex_normals, dtype=np.float32).reshape(-1, 3),
            "colors": np.asarray(mesh.vertex_colors, dtype=np.float32).reshape(-1, 3)}


def points_arrays(points: o3d.geometry.PointCloud) -> dict[str, np.ndarray]:
    return {"positions": np.asarray(points.points, dtype=np.float32).reshape(-1, 3),
            "triangles": np.zeros((0, 3), np.uint32),
            "normals": np.asarray(points.normals, dtype=np.float32).reshape(-1, 3),
            "colors": np.asarray(points.colors, dtype=np.float32).reshape(-1, 3)}


def srgb_to_linear(colors: np.ndarray) -> np.ndarray:
    """sRGB-encoded colours in [0, 1] -> linear (IEC 61966-2-1), as glTF defines vertex colours."""
    c = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(colors: np.ndarray) -> np.ndarray:
    """The inverse of ``srgb_to_linear``."""
    c = np.clip(np.asarray(colors, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, c * 12.92, 1.055 * c ** (1 / 2.4) - 0.055)


def _glb_bytes(arrays: dict[str, np.ndarray], up: str = "+y") -> bytes:
    pos = arrays["positions"]
    n = len(pos)
    doc: dict = {"asset": {"version": "2.0", "generator": "livescene export"}, "scene": 0,
                 "scenes": [{"nodes": [0] if n else []}]}
    if n == 0:  # an accessor of count 0 is invalid glTF: an empty scene instead
        return _glb_pack(doc, b"")
    blob = io.BytesIO()
    views: list[dict] = []
    accessors: list[dict] = []

    def add(data: np.ndarray, component: int, kind: str, target: int, normalized: bool = False,
            bounds: bool = False) -> int:
        while blob.tell() % 4:  # every buffer view starts 4-byte aligned
            blob.write(b"\0")
        raw = np.ascontiguousarray(data).tobytes()
        views.append({"buffer": 0, "byteOffset": blob.tell(), "byteLength": len(raw), "target": target})
        blob.write(raw)
        acc = {"bufferView": len(views) - 1, "componentType": component, "count": len(data), "type": kind}
        if normalized:
            acc["normalized"] = True
        if bounds:
            acc["min"] = np.min(data, axis=0).astype(float).tolist()
            acc["max"] = np.max(data, axis=0).astype(float).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    attributes = {"POSITION": add(pos.astype("<f4"), _FLOAT, "VEC3", _ARRAY_BUFFER, bounds=True)}
    if len(arrays["normals"]) == n:
        normals = arrays["normals"] / np.maximum(np.linalg.norm(arrays["normals"], axis=1, keepdims=True), 1e-12)
        attributes["NORMAL"] = add(normals.astype("<f4"), _FLOAT, "VEC3", _ARRAY_BUFFER)
    if len(arrays["colors"]) == n:
        # glTF's COLOR_0 is linear; the renders are sRGB (as the photos were): converted, and kept as floats so
        # that dark colours keep their steps
        attributes["COLOR_0"] = add(srgb_to_linear(arrays["colors"]).astype("<f4"), _FLOAT, "VEC3", _ARRAY_BUFFER)
    # unlit: the colours already hold the room's light (a radiance field's, as a photo scan's); a viewer without
    # the extension falls back to a matte, non-metallic surface (glTF's default material is metal)
    primitive: dict = {"attributes": attributes, "mode": _POINTS, "material": 0}
    tris = arrays["triangles"]
    if len(tris):
        flat = tris.reshape(-1).astype("<u4")
        primitive["indices"] = add(flat[:, None], _UINT, "SCALAR", _ELEMENT_ARRAY_BUFFER, bounds=True)
        primitive["mode"] = _TRIANGLES
    while blob.tell() % 4:
        blob.write(b"\0")
    body = blob.getvalue()
    node: dict = {"mesh": 0}
    if UP_TO_GLTF_Y[up] is not None:
        node["rotation"] = UP_TO_GLTF_Y[up]
    doc.update({"nodes": [node], "meshes": [{"primitives": [primitive]}], "accessors": accessors,
                "bufferViews": views, "buffers": [{"byteLength": len(body)}],
                "materials": [{"pbrMetallicRoughness": {"metallicFactor": 0.0, "roughnessFactor": 1.0},
                               "extensions": {"KHR_materials_unlit": {}}}],
                "extensionsUsed": ["KHR_materials_unlit"]})
    return _glb_pack(doc, body)


def _glb_pack(doc: dict, body: bytes) -> bytes:
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)  # the JSON chunk is padded with spaces
    chunks = struct.pack("<II", len(js), _CHUNK_JSON) + js
    if body:
        chunks += struct.pack("<II", len(body), _CHUNK_BIN) + body
    return struct.pack("<III", _GLB_MAGIC, 2, 12 + len(chunks)) + chunks


def read_glb(path: str | Path) -> dict[str, np.ndarray]:
    """The first primitive of a GLB written by ``write_glb``: positions, triangles (or empty), colours, mode.

    For checking exports (tests, the benchmark), not a general glTF reader.
    """
    data = Path(path).read_bytes()
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != _GLB_MAGIC or version != 2 or length != len(data):
        raise ValueError(f"{path}: not a glTF 2.0 binary of {len(data)} bytes")
    off, doc, body = 12, {}, b""
    while off < length:
        size, kind = struct.unpack_from("<II", data, off)
        chunk = data[off + 8: off + 8 + size]
        if kind == _CHUNK_JSON:
            doc = json.loads(chunk)
        elif kind == _CHUNK_BIN:
            body = chunk
        off += 8 + size
    if not doc.get("meshes"):
        return {"positions": np.zeros((0, 3), np.float32), "triangles": np.zeros((0, 3), np.uint32),
                "colors": np.zeros((0, 3), np.float32), "mode": np.array(_TRIANGLES)}
    if not body and doc["buffers"][0].get("uri", "").startswith("data:"):
        body = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])
    dtypes = {_FLOAT: "<f4", _UINT: "<u4", _UBYTE: "u1", 5123: "<u2"}
    widths = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}

    def accessor(i: int) -> np.ndarray:
        acc = doc["accessors"][i]
        view = doc["bufferViews"][acc["bufferView"]]
        dt = np.dtype(dtypes[acc["componentType"]])
        width = widths[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", dt.itemsize * width)
        rows = [np.frombuffer(body, dt, width, start + r * stride) for r in range(acc["count"])] \
            if stride != dt.itemsize * width else [np.frombuffer(body, dt, acc["count"] * width, start)]
        return np.concatenate(rows).reshape(acc["count"], width)

    prim = doc["meshes"][0]["primitives"][0]
    attrs = prim["attributes"]
    colors = accessor(attrs["COLOR_0"])[:, :3] if "COLOR_0" in attrs else np.zeros((0, 3))
    if colors.dtype == np.uint8:
        colors = colors.astype(np.float32) / 255.0
    colors = linear_to_srgb(colors)  # glTF's colours are linear; returned as the renders were (sRGB)
    tris = accessor(prim["indices"]).reshape(-1, 3) if "indices" in prim else np.zeros((0, 3), np.uint32)
    return {"positions": accessor(attrs["POSITION"]).astype(np.float32), "triangles": tris.astype(np.uint32),
            "colors": colors.astype(np.float32), "mode": np.array(prim.get("mode", _TRIANGLES))}


def _obj_text(arrays: dict[str, np.ndarray]) -> str:
    pos, cols, normals, tris = arrays["positions"], arrays["colors"], arrays["normals"], arrays["triangles"]
    out = io.StringIO()
    out.write("# livescene export: dataset world coordinates; vertex colours as 'v x y z r g b'\n")
    if len(pos):
        rows = np.hstack([pos, cols]) if len(cols) == len(pos) else pos
        np.savetxt(out, rows, fmt="v" + " %.6g" * rows.shape[1])
    if len(tris):
        has_normals = len(normals) == len(pos)
        if has_normals:
            np.savetxt(out, normals, fmt="vn %.4f %.4f %.4f")
        idx = tris.astype(np.int64) + 1
        if has_normals:
            np.savetxt(out, np.repeat(idx, 2, axis=1), fmt="f %d//%d %d//%d %d//%d")
        else:
            np.savetxt(out, idx, fmt="f %d %d %d")
    return out.getvalue()


def _ply_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """Binary little-endian PLY: float32 x y z (nx ny nz), uchar red green blue, faces as uchar-counted int lists."""
    pos, normals, cols, tris = arrays["positions"], arrays["normals"], arrays["colors"], arrays["triangles"]
    n = len(pos)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    has_normals, has_colors = n > 0 and len(normals) == n, n > 0 and len(cols) == n
    if has_normals:
        fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    if has_colors:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vert = np.empty(n, dtype=fields)
    for k, name in enumerate("xyz"):
        vert[name] = pos[:, k]
    if has_normals:
        for k, name in enumerate(("nx", "ny", "nz")):
            vert[name] = normals[:, k]
    if has_colors:
        rgb = np.clip(cols * 255.0 + 0.5, 0, 255).astype(np.uint8)
        for k, name in enumerate(("red", "green", "blue")):
            vert[name] = rgb[:, k]
    kinds = {"<f4": "float", "u1": "uchar"}
    header = ["ply", "format binary_little_endian 1.0", "comment livescene export (dataset world coordinates)",
              f"element vertex {n}", *(f"property {kinds[t]} {name}" for name, t in fields)]
    if len(tris):
        header += [f"element face {len(tris)}", "property list uchar int vertex_indices"]
    body = vert.tobytes()
    if len(tris):
        face = np.empty(len(tris), dtype=[("n", "u1"), ("i", "<i4", (3,))])
        face["n"], face["i"] = 3, tris.astype(np.int32)
        body += face.tobytes()
    return ("\n".join([*header, "end_header"]) + "\n").encode("ascii") + body


def write_geometry(path: str | Path, geometry: o3d.geometry.TriangleMesh | o3d.geometry.PointCloud,
                   up: str = "+y") -> int:
    """Write a mesh or point cloud in the format of ``path``'s suffix (.ply/.obj/.glb); returns bytes written.

    ``up`` (a key of ``UP_TO_GLTF_Y``) is the world's up axis: a GLB's node turns it to glTF's +y.
    """
    if up not in UP_TO_GLTF_Y:
        raise ValueError(f"up axis {up!r}; choose one of {sorted(UP_TO_GLTF_Y)}")
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower()
    if fmt not in FORMATS:
        raise ValueError(f"{path}: unknown format {fmt!r}; choose one of {FORMATS}")
    is_mesh = isinstance(geometry, o3d.geometry.TriangleMesh)
    with atomic_path(path) as tmp:
        arrays = mesh_arrays(geometry) if is_mesh else points_arrays(geometry)
        if fmt == "ply":
            tmp.write_bytes(_ply_bytes(arrays))
        elif fmt == "glb":
            tmp.write_bytes(_glb_bytes(arrays, up))
        else:
            tmp.write_text(_obj_text(arrays))
    return path.stat().st_size
