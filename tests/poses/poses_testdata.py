"""Test data for the pose stage: a tiny textured room ray-cast with open3d, images with exact poses.

The room is a box with two crates inside (parallax); crate 1 is the "interactive
object" whose pixels form the object mask. Every surface carries a multi-scale
noise texture indexed by its 2D wall coordinates, so SIFT finds plenty of
stable blobs and the true camera poses are known exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d

from stages.scene import Camera, generate_rays, look_at

ROOM_MIN = np.array([-2.0, -1.5, 0.0])
ROOM_MAX = np.array([2.0, 1.5, 2.5])
SMALL_CAMERA = Camera(fx=100.0, fy=100.0, cx=80.0, cy=60.0, width=160, height=120)
"""160x120 keeps a COLMAP run on a dozen frames at a few seconds on two cores."""
CRATES = ((np.array([-0.9, 0.2, 0.0]), np.array([-0.3, 0.8, 0.7])),  # id 1: the interactive object
          (np.array([0.4, -0.6, 0.0]), np.array([1.1, 0.1, 1.0])))


def _box_mesh(lo: np.ndarray, hi: np.ndarray) -> o3d.t.geometry.TriangleMesh:
    mesh = o3d.geometry.TriangleMesh.create_box(*(hi - lo))
    mesh.translate(lo)
    return o3d.t.geometry.TriangleMesh.from_legacy(mesh)


def _texture(seed: int, size: int = 512) -> np.ndarray:
    """Multi-scale blurred noise, contrast-stretched: blob-rich, SIFT-friendly."""
    rng = np.random.default_rng(seed)
    tex = np.zeros((size, size), np.float32)
    for sigma, weight in ((12, 1.0), (5, 0.7), (2, 0.4)):
        tex += weight * cv2.GaussianBlur(rng.standard_normal((size, size)).astype(np.float32), (0, 0), sigma) * sigma
    tex = (tex - tex.mean()) / (tex.std() + 1e-6)
    return np.clip(0.5 + 0.22 * tex, 0, 1)


@dataclass
class SyntheticRoom:
    """Ray-casts the textured room from any OpenGL camera-to-world pose."""

    camera: Camera
    seed: int = 0

    def __post_init__(self) -> None:
        self.scene = o3d.t.geometry.RaycastingScene()
        room = _box_mesh(ROOM_MIN, ROOM_MAX)
        self.ids = [self.scene.add_triangles(room)]
        self.ids += [self.scene.add_triangles(_box_mesh(lo, hi)) for lo, hi in CRATES]
        self.textures = [_texture(self.seed + k) for k in range(3 * len(self.ids))]
        self.colors = np.random.default_rng(self.seed).uniform(0.4, 1.0, (len(self.ids), 3))

    def render(self, c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(BGR uint8 image, id map: 0 background, 1 the interactive crate, 2 the other crate)."""
        origins, dirs = generate_rays(self.camera, c2w)
        rays = np.concatenate([origins, dirs], -1).astype(np.float32)
        hit = self.scene.cast_rays(o3d.core.Tensor(rays))
        t = hit["t_hit"].numpy()
        geom = hit["geometry_ids"].numpy().astype(np.int64)
        normals = np.abs(hit["primitive_normals"].numpy())
        points = origins + t[..., None] * dirs
        axis = np.argmax(normals, -1)  # which axis the surface faces: texture the other two
        u = np.where(axis == 0, points[..., 1], points[..., 0])
        v = np.where(axis == 2, points[..., 1], points[..., 2])
        gray = np.zeros(t.shape, np.float32)
        for g in range(len(self.ids)):
            for a in range(3):
                sel = (geom == self.ids[g]) & (axis == a)
                tex = self.textures[3 * g + a]
                px = ((u[sel] * 150.0) % tex.shape[1]).astype(np.int64)
                py = ((v[sel] * 150.0) % tex.shape[0]).astype(np.int64)
                gray[sel] = tex[py, px]
        rgb = gray[..., None] * self.colors[np.clip(geom, 0, len(self.ids) - 1)]
        image = np.clip(rgb * 255, 0, 255).astype(np.uint8)[..., ::-1]
        ids = np.where(geom == self.ids[1], 1, np.where(geom == self.ids[2], 2, 0)).astype(np.uint8)
        return np.ascontiguousarray(image), ids


def orbit_poses(n: int, radius: float = 1.2, arc_deg: float = 70.0, height: float = 1.3) -> list[np.ndarray]:
    """Camera centres on an arc inside the room, looking across it (translation gives parallax)."""
    out = []
    for k in range(n):
        a = np.deg2rad(-arc_deg / 2 + arc_deg * k / max(n - 1, 1)) - np.pi / 2
        eye = np.array([radius * np.cos(a), 0.3 + radius * np.sin(a) * 0.6, height])
        target = np.array([0.6 * np.cos(a + np.pi), 1.5, 0.8])
        out.append(look_at(eye, target))
    return out


def write_sequence(root: Path, poses: list[np.ndarray], camera: Camera | None = None,
                   source_indices: list[int] | None = None, seed: int = 0,
                   noise_std: float = 0.0) -> tuple[Path, Path, Camera]:
    """Render ``poses`` to ``root/images/frame_XXXXX.png`` and id maps to ``root/masks``.

    ``seed`` picks the textures (another seed = a room no other frame matches); ``noise_std`` adds
    per-frame sensor noise (grey levels) so that frames of a still camera are not byte-identical.
    """
    camera = camera or SMALL_CAMERA
    room = SyntheticRoom(camera, seed=seed)
    rng = np.random.default_rng(seed)
    images, masks = root / "images", root / "masks"
    images.mkdir(parents=True, exist_ok=True)
    masks.mkdir(parents=True, exist_ok=True)
    for k, c2w in enumerate(poses):
        i = source_indices[k] if source_indices else k
        image, ids = room.render(c2w)
        if noise_std > 0:
            image = np.clip(image + rng.normal(0, noise_std, image.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(images / f"frame_{i:05d}.png"), image)
        cv2.imwrite(str(masks / f"frame_{i:05d}.png"), ids)
    return images, masks, camera
