"""A thumbnail of an exported mesh, rendered headless by ray casting (docs/export.md, "Thumbnails").

open3d's ``OffscreenRenderer`` needs EGL or Vulkan, which a headless CPU machine does not have
("Failed to load vulkan library" here); its CPU ``RaycastingScene`` needs neither. Each pixel shows
the hit triangle's interpolated vertex colour, shaded by the angle to the viewing ray so that the
shape reads; pixels that miss show white, like the renders.
"""

from __future__ import annotations

import cv2
import numpy as np
import open3d as o3d

from stages.scene import Camera, atomic_path, generate_rays

AMBIENT = 0.45
"""Share of the colour kept on surfaces seen edge-on (the rest scales with the cosine to the ray)."""


def raycast_mesh(mesh: o3d.geometry.TriangleMesh, camera: Camera, c2w: np.ndarray) -> np.ndarray:
    """RGB float32 [H, W, 3] of ``mesh`` seen from ``c2w`` (OpenGL axes); white where nothing is hit."""
    h, w = camera.height, camera.width
    verts = np.asarray(mesh.vertices, dtype=np.float32)
    tris = np.asarray(mesh.triangles, dtype=np.uint32)
    if len(tris) == 0:
        return np.ones((h, w, 3), np.float32)
    colors = np.asarray(mesh.vertex_colors, dtype=np.float32)
    if len(colors) != len(verts):
        colors = np.full((len(verts), 3), 0.7, np.float32)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(verts), o3d.core.Tensor(tris))
    origins, dirs = generate_rays(camera, c2w)
    rays = np.concatenate([origins.reshape(-1, 3), dirs.reshape(-1, 3)], axis=1).astype(np.float32)
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    hit = np.isfinite(ans["t_hit"].numpy())
    prim = np.where(hit, ans["primitive_ids"].numpy().astype(np.int64), 0)
    uv = ans["primitive_uvs"].numpy()
    corner = tris[prim]  # [N, 3]: barycentric weights (1 - u - v, u, v)
    bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
    colour = np.einsum("nk,nkc->nc", bary, colors[corner])
    normal = ans["primitive_normals"].numpy()
    cosine = np.abs(np.sum(normal * rays[:, 3:], axis=1))
    shaded = colour * (AMBIENT + (1.0 - AMBIENT) * cosine)[:, None]
    out = np.where(hit[:, None], shaded, 1.0)
    return np.clip(out, 0.0, 1.0).reshape(h, w, 3).astype(np.float32)


def overview_view(camera: Camera, c2ws: list[np.ndarray], width: int = 320,
                  widen: float = 1.6) -> tuple[Camera, np.ndarray]:
    """Camera and pose of a thumbnail: the middle training pose with a wider field of view.

    Moving the camera back would show more, but in a room it soon passes through the wall behind
    the training cameras; widening the view (focal / ``widen``) stays inside what they saw.
    """
    factor = width / camera.width
    cam = camera.scaled(factor)
    cam = Camera(fx=cam.fx / widen, fy=cam.fy / widen, cx=cam.cx, cy=cam.cy, width=cam.width, height=cam.height)
    return cam, np.asarray(c2ws[len(c2ws) // 2], dtype=np.float64)


def write_thumbnail(path, mesh: o3d.geometry.TriangleMesh, camera: Camera, c2w: np.ndarray) -> None:
    img = raycast_mesh(mesh, camera, c2w)
    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), (img[..., ::-1] * 255.0 + 0.5).astype(np.uint8)):
            raise OSError(f"{path}: OpenCV could not write the PNG")
