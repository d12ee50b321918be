"""The ray-cast renderer: changing one object's state changes pixels only where it sweeps and shadows."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from stages.capture import SceneRenderer
from stages.capture.camera_path import camera_path
from stages.scene import generate_rays

VISIBLE = 0.5 / 255  # half an 8-bit grey level


def test_state_change_is_local_to_swept_region_and_shadow(small_spec):
    spec = small_spec(n_frames=8, width=96, height=72)
    renderer = SceneRenderer(spec)
    pose = camera_path(spec)[2]
    base = np.array([0.0, 0.3])
    for k in range(2):  # each object in turn
        moved = base.copy()
        moved[k] = 1.0
        a, b = renderer.render(pose, base), renderer.render(pose, moved)
        changed = np.abs(a["rgb"] - b["rgb"]).max(axis=-1) > VISIBLE
        swept = np.zeros(changed.shape, dtype=bool)
        for s in np.linspace(base[k], moved[k], 9):
            states = base.copy()
            states[k] = s
            swept |= renderer.render(pose, states)["ids"] == k + 1
        shadow = (a["shadow_ids"] == k + 1).any(axis=0) | (b["shadow_ids"] == k + 1).any(axis=0)
        allowed = swept | shadow
        assert changed.sum() > 20, f"object {k} moved but almost nothing changed"
        assert allowed.mean() < 0.5
        outside = changed & ~allowed
        assert not outside.any(), f"object {k}: {outside.sum()} changed pixels outside its sweep and shadow"


def test_render_is_deterministic_and_depth_is_z_depth(small_spec):
    spec = small_spec(n_frames=4, width=48, height=36)
    pose = camera_path(spec)[1]
    renderer = SceneRenderer(spec)
    a = renderer.render(pose, [0.2, 0.7])
    b = SceneRenderer(spec).render(pose, {"cabinet": 0.2, "drawer": 0.7})
    for key in ("rgb", "depth", "ids"):
        assert np.array_equal(a[key], b[key])
    # an independent cast of the same geometry: depth = ray length x cos(angle to the viewing axis)
    verts, tris = renderer.model.mesh(renderer.model.part_poses(np.array([0.2, 0.7])))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(verts), o3d.core.Tensor(tris))
    origins, dirs = generate_rays(renderer.camera, pose)
    rays = np.concatenate([origins, dirs], axis=-1).reshape(-1, 6).astype(np.float32)
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().reshape(a["depth"].shape)
    cos = dirs @ (-pose[:3, 2])
    assert cos.min() < 0.9  # the corners are far enough off-axis to tell z-depth from ray length
    np.testing.assert_allclose(a["depth"], t_hit * cos, rtol=1e-4)
