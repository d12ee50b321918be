"""TSDF fusion, depth filtering and object pixels on scenes with a known answer."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from stages.export.object_parts import object_pixels
from stages.export.tsdf_fusion import (
    FusionSettings,
    TSDFFusion,
    canonical_order,
    depth_edges,
    fusable_depth,
    intrinsic_matrix,
    ray_distance_to_z,
    world_to_opencv_camera,
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
    # the threshold itself belongs to the object (docs/export.md: probability >= --prob-threshold)
    assert object_pixels(probs, 0, 0.9, erode_px=0).sum() == 25


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
    ordered = np.asarray(a.triangles)
    assert np.array_equal(ordered[:, 0], ordered.min(axis=1))  # each face starts at its smallest vertex


def test_open3d_intrinsics_put_a_pixels_centre_on_its_integer_index():
    """open3d's pixel centres are at integers, this project's at +0.5: the ray through pixel (u, v) projects to
    (u, v) exactly, else the mesh sits half a pixel off the renders (and off the point cloud)."""
    k = intrinsic_matrix(CAMERA)
    for u, v in ((0, 0), (47, 35), (10, 30)):
        x = (u + 0.5 - CAMERA.cx) / CAMERA.fx  # the ray's direction in OpenCV camera axes, z = 1
        y = (v + 0.5 - CAMERA.cy) / CAMERA.fy
        assert np.allclose(k @ np.array([x, y, 1.0]), [u, v, 1.0], atol=1e-12)
    # the extrinsic maps world to OpenCV camera axes: a camera 2 above the origin, looking down, sees it 2 ahead
    c2w = look_at(np.array([0.0, 0.0, 2.0]), np.zeros(3), up=(0.0, 1.0, 0.0))
    assert np.allclose(world_to_opencv_camera(c2w) @ [0.0, 0.0, 0.0, 1.0], [0.0, 0.0, 2.0, 1.0], atol=1e-12)


def test_one_view_makes_no_surface_two_views_do():
    """A voxel is meshed where two views at least saw it (weight >= 1.5, docs/export.md): one stray view is no
    surface. The fused pixels are counted and the points stay in the box."""
    box = np.array([[-1.0, -1.0, -0.5], [1.0, 1.0, 1.0]])
    settings = FusionSettings(voxel=0.02)
    fusion = TSDFFusion(box, settings)
    c2w, dist, rgb = _plane_view(np.array([0.0, 0.0, 2.0]))
    z = fusable_depth(CAMERA, dist, np.ones(dist.shape), settings)
    z[:, :10] = 0.0  # 10 columns not fused
    fusion.integrate(CAMERA, c2w, rgb, z)
    assert fusion.pixels_fused == 36 * 38
    assert len(fusion.extract_mesh().vertices) == 0
    fusion.integrate(CAMERA, c2w, rgb, z)
    assert fusion.pixels_fused == 2 * 36 * 38
    mesh = fusion.extract_mesh()
    assert len(mesh.vertices) > 100
    # normals are written with the mesh (ply, glb): on the plane z = 0 they are vertical
    assert mesh.has_vertex_normals() and np.abs(np.asarray(mesh.vertex_normals)[:, 2]).min() > 0.9
    # the view covers 2.4 x 1.8 at that distance, wider than the box: the points are cropped to it
    p = np.asarray(fusion.extract_points().points)
    assert len(p) > 100 and np.all(p >= box[0]) and np.all(p <= box[1])
    assert np.abs(p[:, 0]).max() > 0.95


def test_an_edge_across_the_rows_and_an_accumulation_of_one_half():
    """The depth filter looks at all four neighbours (an edge between rows too); accumulation >= 0.5 is fused."""
    z = np.full((10, 10), 2.0)
    z[5:, :] = 4.0
    edges = depth_edges(z, 0.05)
    assert edges[4:6, :].all() and not edges[:4].any() and not edges[6:].any()
    cam = Camera(fx=10.0, fy=10.0, cx=5.0, cy=5.0, width=10, height=10)
    v, u = np.meshgrid(np.arange(10), np.arange(10), indexing="ij")
    distance = 2.0 * np.linalg.norm(pixel_directions(cam, u, v), axis=-1)
    acc = np.full((10, 10), 0.5)
    acc[0, 0] = 0.49
    out = fusable_depth(cam, distance, acc, FusionSettings(voxel=0.1))
    assert out[0, 0] == 0 and np.allclose(out.reshape(-1)[1:], 2.0)


def test_a_distorted_view_is_refused_rather_than_fused_as_a_pinhole():
    """open3d projects voxels through the 3x3 intrinsics alone: a view with k1 = -0.1 would put the corner pixels of
    this 48x36 camera (0.73 focal lengths out) 0.1 x 0.73^3 x 40 = 1.6 px off their rays, so fusion takes pinhole
    views only."""
    lens = Camera(fx=40.0, fy=40.0, cx=24.0, cy=18.0, width=48, height=36, distortion={"k1": -0.1})
    fusion = TSDFFusion(np.array([[-1.0] * 3, [1.0] * 3]), FusionSettings(voxel=0.05))
    with pytest.raises(ValueError, match=r"lens distortion.*render the view through a pinhole camera"):
        fusion.integrate(lens, np.eye(4), np.zeros((36, 48, 3)), np.ones((36, 48), np.float32))
    assert fusion.pixels_fused == 0
