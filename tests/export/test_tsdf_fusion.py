"""TSDF fusion, depth filtering and object pixels on scenes with a known answer."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from stages.export.object_parts import object_pixels
from stages.export.tsdf_fusion import (
    FusionSettings,
    TSDFFusion,
    canonical_order,
    depth_edges,
    fusable_depth,
    ray_distance_to_z,
)
from stages.scene import Camera, generate_rays, look_at
from stages.scene.camera import pixel_directions

CAMERA = Camera(fx=40.0, fy=40.0, cx=24.0, cy=18.0, width=48, height=36)


def _plane_view(eye: np.ndarray, plane_z: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(c2w, distance along each ray to the plane z = plane_z, colour) for a camera above it looking down."""
    c2w = look_at(eye, np.array([0.0, 0.0, plane_z]), up=(0.0, 1.0, 0.0))
    origins, dirs = generate_rays(CAMERA, c2w)
    t = (plane_z - origins[..., 2]) / dirs[..., 2]
    rgb = np.zeros((*t.shape, 3))
    rgb[..., 0] = 0.8
    return c2w, t, rgb


def test_ray_distance_becomes_depth_along_the_axis():
    _, dist, _ = _plane_view(np.array([0.0, 0.0, 2.0]))
    z = ray_distance_to_z(CAMERA, dist)
    assert np.allclose(z, 2.0, atol=1e-9)  # a fronto-parallel plane has one depth
    assert dist.max() > 2.05  # while the distance along the rays grows towards the corners


def test_depth_edges_and_transparent_pixels_are_not_fused():
    z = np.full((10, 10), 2.0)
    z[:, 5:] = 4.0
    edges = depth_edges(z, 0.05)
    assert edges[:, 4:6].all() and not edges[:, :4].any() and not edges[:, 6:].any()
    cam = Camera(fx=10.0, fy=10.0, cx=5.0, cy=5.0, width=10, height=10)
    v, u = np.meshgrid(np.arange(10), np.arange(10), indexing="ij")
    distance = z * np.linalg.norm(pixel_directions(cam, u, v), axis=-1)
    acc = np.ones((10, 10))
    acc[0, 0] = 0.1  # the field is transparent there
    out = fusable_depth(cam, distance, acc, FusionSettings(voxel=0.1))
    assert out[0, 0] == 0 and (out[:, 4:6] == 0).all()
    assert np.allclose(out[1:, :4], 2.0) and np.allclose(out[:, 6:], 4.0)


def test_fusion_recovers_a_plane_inside_the_box_with_its_colour():
    box = np.array([[-1.0, -1.0, -0.5], [1.0, 1.0, 1.0]])
    settings = FusionSettings(voxel=0.02)
    fusion = TSDFFusion(box, settings)
    for eye in ([0.0, 0.0, 2.0], [0.3, 0.0, 1.9], [0.0, -0.3, 1.9]):
        c2w, dist, rgb = _plane_view(np.array(eye))
        fusion.integrate(CAMERA, c2w, rgb, fusable_depth(CAMERA, dist, np.ones(dist.shape), settings))
    mesh = fusion.extract_mesh()
    verts = np.asarray(mesh.vertices)
    assert len(verts) > 500 and len(mesh.triangles) > 500
    assert np.abs(verts[:, 2]).max() < settings.voxel  # on the plane z = 0, to within a voxel
    assert np.all(verts >= box[0]) and np.all(verts <= box[1])
    assert np.allclose(np.asarray(mesh.vertex_colors).mean(0), [0.8, 0.0, 0.0], atol=0.02)
    points = fusion.extract_points()
    p = np.asarray(points.points)
    assert len(p) > 500 and np.abs(p[:, 2]).max() < 1e-6
    # one point per voxel: no two closer than the voxel's diagonal allows a duplicate
    assert len(p) <= (2.0 / settings.voxel) ** 2 * 1.1


def test_nothing_fused_gives_empty_geometry():
    fusion = TSDFFusion(np.array([[-1.0] * 3, [1.0] * 3]), FusionSettings(voxel=0.05))
    fusion.integrate(CAMERA, np.eye(4), np.zeros((36, 48, 3)), np.zeros((36, 48), np.float32))
    assert len(fusion.extract_mesh().vertices) == 0 and len(fusion.extract_points().points) == 0


def test_object_pixels_threshold_and_erosion():
    probs = np.zeros((9, 9, 3))
    probs[..., 2] = 1.0
    probs[2:7, 2:7, 0], probs[2:7, 2:7, 2] = 0.9, 0.1
    mask = object_pixels(probs, 0, 0.5, erode_px=1)
    assert mask.sum() == 9 and mask[3:6, 3:6].all()  # the 5x5 square eroded to its 3x3 core
    assert object_pixels(probs, 0, 0.95, erode_px=0).sum() == 0
    assert object_pixels(probs, 1, 0.5).sum() == 0


def _face_set(positions: np.ndarray, faces: np.ndarray) -> set:
    """Each face as its corner positions, turned to start at the smallest corner (winding kept)."""
    out = set()
    for f in faces:
        corners = [tuple(positions[i]) for i in f]
        k = corners.index(min(corners))
        out.add(tuple(corners[k:] + corners[:k]))
    return out


def test_canonical_order_gives_the_same_arrays_for_any_vertex_and_face_order():
    rng = np.random.default_rng(0)
    mesh = o3d.geometry.TriangleMesh.create_sphere(radius=1.0, resolution=12)
    mesh.vertex_colors = o3d.utility.Vector3dVector(rng.random((len(mesh.vertices), 3)))
    positions, faces = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
    # the same mesh as another run of marching cubes might emit it: vertices permuted, faces turned and shuffled
    perm = rng.permutation(len(positions))
    shuffled = o3d.geometry.TriangleMesh()
    shuffled.vertices = o3d.utility.Vector3dVector(positions[perm])
    shuffled.vertex_colors = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_colors)[perm])
    inverse = np.argsort(perm)
    turned = np.take_along_axis(inverse[faces], (np.arange(3)[None] + rng.integers(0, 3, (len(faces), 1))) % 3, 1)
    shuffled.triangles = o3d.utility.Vector3iVector(turned[rng.permutation(len(turned))].astype(np.int32))
    a, b = canonical_order(mesh), canonical_order(shuffled)
    for name in ("vertices", "triangles", "vertex_colors"):
        assert np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name))), name
    a.compute_vertex_normals()
    b.compute_vertex_normals()
    assert np.array_equal(np.asarray(a.vertex_normals), np.asarray(b.vertex_normals))
    # the same surface: every face with its corners and winding
    assert _face_set(np.asarray(a.vertices), np.asarray(a.triangles)) == _face_set(positions, faces)
    assert np.all(np.diff(np.asarray(a.vertices)[:, 0]) >= 0)
