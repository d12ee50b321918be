"""Fuse rendered depth and colour into a sparse TSDF volume (open3d ``VoxelBlockGrid``) -> mesh and points.

A radiance field has no surface; its expected ray-termination distance is one. Rendered at many
training poses and fused into a truncated signed distance volume, the views average each other's
noise and marching cubes gives a coloured mesh (docs/export.md, "How the geometry is made"). Only
pixels the field covers (accumulation high) and that are not on a depth edge (where the expected
depth mixes foreground and background) are fused.

The volume is open3d's ``t.geometry.VoxelBlockGrid``, the hashed-block successor of the legacy
``pipelines.integration.ScalableTSDFVolume``: in the pinned open3d 0.20 wheel the legacy class
allocates no voxel at all (a 640x480 plane at 2 m integrated five times extracts 0 points and 0
vertices; docs/export.md has the snippet), while ``UniformTSDFVolume`` works but is dense. The
point cloud is the fused pixels themselves, back-projected with their rendered colours and
thinned to one point per voxel: the block grid's own point extraction returns a small fraction
of the surface in this version.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import open3d as o3d
import open3d.core as o3c

from stages.scene import Camera, opengl_to_opencv
from stages.scene.camera import pixel_directions


def canonical_order(mesh: o3d.geometry.TriangleMesh) -> o3d.geometry.TriangleMesh:
    """The same mesh with its vertices sorted by position (then colour), each triangle turned (winding kept) to
    start at its smallest vertex, and the triangles sorted.

    Marching cubes on the block grid emits vertices and faces in an order that varies from run to run (its
    blocks are visited in parallel), so the same fused volume gave other files; in this order it gives the same
    bytes (docs/export.md, "Reproducible files"). Normals are not carried: compute them afterwards.
    """
    positions = np.asarray(mesh.vertices)
    colors = np.asarray(mesh.vertex_colors)
    triangles = np.asarray(mesh.triangles)
    keys = [positions[:, 2], positions[:, 1], positions[:, 0]]
    if len(colors):
        keys = [colors[:, 2], colors[:, 1], colors[:, 0], *keys]
    order = np.lexsort(keys)  # the last key is the primary one: x, then y, z, then colour
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    faces = rank[triangles]
    turn = (np.arange(3)[None, :] + faces.argmin(axis=1)[:, None]) % 3
    faces = np.take_along_axis(faces, turn, axis=1)
    faces = faces[np.lexsort((faces[:, 2], faces[:, 1], faces[:, 0]))]
    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(positions[order]),
                                    o3d.utility.Vector3iVector(faces.astype(np.int32)))
    if len(colors):
        out.vertex_colors = o3d.utility.Vector3dVector(colors[order])
    return out


@dataclass(frozen=True)
class FusionSettings:
    """Voxel size and the depth filters of the fusion (docs/export.md has the defaults and why)."""

    voxel: float
    """Voxel edge, dataset units."""
    trunc_voxels: float = 5.0
    """Truncation distance of the signed distance, in voxels (NeRF depth is noisier than a sensor's)."""
    min_accumulation: float = 0.5
    """Pixels whose rendered opacity is below this are not fused (rays that leave the box unhit)."""
    edge_ratio: float = 0.05
    """A pixel whose depth differs from a 4-neighbour's by more than this fraction is on an edge: not fused."""
    min_weight: float = 1.5
    """Marching cubes keeps voxels seen by at least this many views (2: one stray view makes no surface)."""


def ray_distance_to_z(camera: Camera, distance: np.ndarray) -> np.ndarray:
    """Distance along each pixel's ray (what ``LoadedRun.render`` returns) -> depth along the optical axis."""
    v, u = np.meshgrid(np.arange(camera.height), np.arange(camera.width), indexing="ij")
    dirs = pixel_directions(camera, u, v)  # z = -1: the norm is 1 / cos(angle to the axis)
    return np.asarray(distance, dtype=np.float64) / np.linalg.norm(dirs, axis=-1)


def depth_edges(z: np.ndarray, ratio: float) -> np.ndarray:
    """Pixels whose depth jumps by more than ``ratio`` of their own depth to any 4-neighbour."""
    pad = np.pad(z, 1, mode="edge")
    jumps = [np.abs(pad[1:-1, 1:-1] - pad[1 + dy:pad.shape[0] - 1 + dy, 1 + dx:pad.shape[1] - 1 + dx])
             for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1))]
    return np.max(jumps, axis=0) > ratio * np.maximum(z, 1e-9)


def fusable_depth(camera: Camera, distance: np.ndarray, accumulation: np.ndarray,
                  settings: FusionSettings) -> np.ndarray:
    """z-depth [H, W] float32 with 0 (= not fused) where the field is transparent or on a depth edge."""
    z = ray_distance_to_z(camera, distance)
    bad = (np.asarray(accumulation) < settings.min_accumulation) | ~np.isfinite(z) | (z <= 0)
    if settings.edge_ratio > 0:
        bad |= depth_edges(np.where(np.isfinite(z), z, 0.0), settings.edge_ratio)
    return np.where(bad, 0.0, z).astype(np.float32)


def intrinsic_matrix(camera: Camera) -> np.ndarray:
    # open3d puts pixel centres at integers, this project at +0.5 (stages/scene/camera.py)
    return np.array([[camera.fx, 0.0, camera.cx - 0.5], [0.0, camera.fy, camera.cy - 0.5], [0.0, 0.0, 1.0]])


def world_to_opencv_camera(c2w: np.ndarray) -> np.ndarray:
    """open3d's extrinsic: world -> camera in OpenCV axes (x right, y down, z forward)."""
    return np.linalg.inv(opengl_to_opencv(np.asarray(c2w, dtype=np.float64)))


def back_project(camera: Camera, c2w: np.ndarray, z_depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World points [N, 3] of the pixels with z > 0, and their flat pixel indices [N]."""
    idx = np.flatnonzero(np.asarray(z_depth).reshape(-1) > 0)
    v, u = np.divmod(idx, camera.width)
    dirs = pixel_directions(camera, u, v)  # OpenGL camera axes, z = -1
    cam = dirs * np.asarray(z_depth).reshape(-1)[idx, None]
    c2w = np.asarray(c2w, dtype=np.float64)
    return cam @ c2w[:3, :3].T + c2w[:3, 3], idx


class TSDFFusion:
    """One TSDF volume plus the fused points: integrate views, then extract a mesh and a point cloud in a box."""

    def __init__(self, box: np.ndarray, settings: FusionSettings, block_count: int = 20000) -> None:
        self.box = np.asarray(box, dtype=np.float64).reshape(2, 3)
        self.settings = settings
        self.grid = o3d.t.geometry.VoxelBlockGrid(
            attr_names=("tsdf", "weight", "color"), attr_dtypes=(o3c.float32, o3c.float32, o3c.float32),
            attr_channels=(1, 1, 3), voxel_size=float(settings.voxel), block_resolution=8,
            block_count=block_count, device=o3c.Device("CPU:0"))
        self.pixels_fused = 0
        self._far = float(np.linalg.norm(self.box[1] - self.box[0])) * 2.0
        self._points: list[np.ndarray] = []
        self._colors: list[np.ndarray] = []

    def integrate(self, camera: Camera, c2w: np.ndarray, rgb: np.ndarray, z_depth: np.ndarray) -> None:
        """Fuse one view: ``rgb`` [H, W, 3] in [0, 1], ``z_depth`` [H, W] (0 = skip the pixel).

        ``camera`` must be a pinhole: open3d projects the voxels through ``intrinsic_matrix`` alone, so a distorted
        view would land its pixels up to the distortion's shift off their rays (the exporter renders pinhole views,
        ``render_camera``; docs/export.md, "How the geometry is made")."""
        if camera.has_distortion:
            raise ValueError(f"TSDF fusion of a camera with lens distortion {camera.distortion}: open3d projects "
                             "without it; render the view through a pinhole camera (exporter.render_camera)")
        valid = int(np.count_nonzero(z_depth))
        if valid == 0:
            return
        depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(z_depth, dtype=np.float32)))
        colour = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(np.clip(rgb, 0, 1), dtype=np.float32)))
        k = o3c.Tensor(intrinsic_matrix(camera), o3c.float64)
        ext = o3c.Tensor(world_to_opencv_camera(c2w), o3c.float64)
        trunc = float(self.settings.trunc_voxels)
        try:
            blocks = self.grid.compute_unique_block_coordinates(depth, k, ext, 1.0, self._far, trunc)
        except RuntimeError as exc:  # open3d samples the depth with a stride: a few scattered pixels may touch none
            if "No block is touched" in str(exc):
                return
            raise
        self.grid.integrate(blocks, depth, colour, k, k, ext, 1.0, self._far, trunc)
        points, idx = back_project(camera, c2w, z_depth)
        self._points.append(points.astype(np.float32))
        self._colors.append(np.asarray(rgb, dtype=np.float32).reshape(-1, 3)[idx])
        self.pixels_fused += valid

    def _crop_box(self) -> o3d.geometry.AxisAlignedBoundingBox:
        return o3d.geometry.AxisAlignedBoundingBox(self.box[0], self.box[1])

    def extract_mesh(self) -> o3d.geometry.TriangleMesh:
        """Marching-cubes mesh with vertex colours, cropped to the box (empty when nothing was fused)."""
        if self.pixels_fused == 0:
            return o3d.geometry.TriangleMesh()
        mesh = self.grid.extract_triangle_mesh(weight_threshold=float(self.settings.min_weight)).to_legacy()
        if len(mesh.vertices) == 0:
            return o3d.geometry.TriangleMesh()
        mesh = mesh.crop(self._crop_box())
        mesh.remove_unreferenced_vertices()
        mesh = canonical_order(mesh)
        mesh.compute_vertex_normals()  # after the ordering: a vertex normal sums its faces in triangle order
        return mesh

    def extract_points(self) -> o3d.geometry.PointCloud:
        """The fused pixels as a coloured point cloud, one point per voxel, cropped to the box."""
        cloud = o3d.geometry.PointCloud()
        if self.pixels_fused == 0:
            return cloud
        cloud.points = o3d.utility.Vector3dVector(np.concatenate(self._points).astype(np.float64))
        cloud.colors = o3d.utility.Vector3dVector(np.concatenate(self._colors).astype(np.float64))
        return cloud.crop(self._crop_box()).voxel_down_sample(float(self.settings.voxel))
