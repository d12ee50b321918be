"""What the renderer takes from the spec: states, mask scope, Lambertian lights and shadows, supersampling, texels."""

from __future__ import annotations

import numpy as np
import pytest

from stages.capture import SceneRenderer
from stages.capture.camera_path import camera_path

STATES = [0.6, 0.3]  # cabinet door and drawer partly open


def _render(spec, **kwargs):
    return SceneRenderer(spec).render(camera_path(spec)[0], STATES, **kwargs)


@pytest.fixture
def spec(small_spec):
    return small_spec(n_frames=2, width=48, height=36)


def test_objects_left_out_of_a_mapping_are_closed_and_a_wrong_count_is_refused(spec):
    renderer = SceneRenderer(spec)
    np.testing.assert_array_equal(renderer.state_vector({"drawer": 0.3}), [0.0, 0.3])
    np.testing.assert_array_equal(renderer.state_vector(None), [0.0, 0.0])
    with pytest.raises(ValueError, match="expected 2 states"):
        renderer.state_vector([0.5])
    with pytest.raises(KeyError, match="window"):
        renderer.state_vector({"window": 1.0})


def test_mask_scope_moving_leaves_the_carcass_out_of_the_masks(spec):
    whole = _render(spec)["ids"]
    spec.mask_scope = "moving"
    moving = _render(spec)["ids"]
    for k in (1, 2):
        assert ((moving == k) <= (whole == k)).all(), "a moving-part pixel outside its object"
        assert 0 < (moving == k).sum() < (whole == k).sum(), f"object {k}: the carcass is still in the mask"
    assert set(np.unique(moving)) <= {0, 1, 2}


def test_shading_is_ambient_plus_each_light_where_it_is_not_shadowed(spec):
    """albedo x (ambient + intensity x n.l x visible): light intensity 0 leaves albedo x ambient."""
    (light,) = spec.render.lights
    assert light.shadows and spec.render.shadows
    lit = _render(spec)
    intensity = light.intensity
    light.intensity = 0.0
    dark = _render(spec)["rgb"]
    light.intensity = 2 * intensity
    bright = _render(spec)["rgb"]
    light.intensity = 0.0
    spec.render.ambient *= 2
    dark_twice = _render(spec)["rgb"]

    shadowed = lit["shadow_ids"][0] != 0
    assert shadowed.any() and (lit["shadow_ids"] == -1).any(), "the room casts no shadow (-1) in this view"
    # a pixel in the shadow of the only light sees only the ambient term
    np.testing.assert_allclose(lit["rgb"][shadowed], dark[shadowed], atol=1e-6)
    # elsewhere the light adds albedo x intensity x n.l: twice the intensity adds twice as much
    unclipped = (bright < 1.0) & (dark_twice < 1.0)
    np.testing.assert_allclose((bright - dark)[unclipped], 2 * (lit["rgb"] - dark)[unclipped], atol=1e-5)
    assert ((lit["rgb"] - dark).max(axis=-1) > 0.02)[~shadowed].mean() > 0.5
    # faces turned away from the light (n.l < 0; here the sides of the cabinet, drawer and table facing the
    # camera at -x) get no light either, without being shadowed
    away = ~shadowed & (np.abs(lit["rgb"] - dark).max(axis=-1) == 0)
    assert away.sum() > 50, away.sum()
    np.testing.assert_allclose(dark_twice[unclipped], 2 * dark[unclipped], atol=1e-5)


@pytest.mark.parametrize("switch", ["master", "light"])
def test_shadows_off_in_the_spec_casts_no_shadow_rays(spec, switch):
    with_shadows = _render(spec)
    no_rays = _render(spec, shadows=False)
    assert not np.array_equal(with_shadows["rgb"], no_rays["rgb"])
    if switch == "master":
        spec.render.shadows = False
    else:
        spec.render.lights[0].shadows = False
    off = _render(spec)
    np.testing.assert_array_equal(off["rgb"], no_rays["rgb"])
    assert not off["shadow_ids"].any()


def test_supersampling_is_the_box_filter_of_the_finer_image(spec):
    renderer = SceneRenderer(spec)
    pose = camera_path(spec)[0]
    fine = renderer.render(pose, STATES, renderer.camera.scaled(2), supersample=1)
    coarse = renderer.render(pose, STATES, supersample=2)
    h, w = coarse["ids"].shape
    np.testing.assert_allclose(coarse["rgb"], fine["rgb"].reshape(h, 2, w, 2, 3).mean(axis=(1, 3)), atol=1e-6)
    plain = renderer.render(pose, STATES, supersample=1)
    assert not np.allclose(coarse["rgb"], plain["rgb"], atol=1e-3)
    np.testing.assert_array_equal(coarse["ids"], plain["ids"])  # ids and depth stay at pixel centres
    spec.render.supersample = 2  # the spec's value is the default
    np.testing.assert_array_equal(SceneRenderer(spec).render(pose, STATES)["rgb"], coarse["rgb"])


def test_texels_per_metre_scales_the_texture_not_the_geometry(spec):
    a = _render(spec)
    spec.render.texels_per_metre *= 2
    b = _render(spec)
    assert np.abs(a["rgb"] - b["rgb"]).max() > 0.1
    np.testing.assert_array_equal(a["ids"], b["ids"])
    np.testing.assert_array_equal(a["depth"], b["depth"])
