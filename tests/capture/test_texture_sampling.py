"""Texture lookups: bilinear between texel centres, wrapping at the edges; contrast 0 leaves the base colour."""

from __future__ import annotations

import numpy as np

from stages.capture.geometry import Material
from stages.capture.textures import make_texture, sample_atlas


def test_sample_atlas_is_bilinear_between_texel_centres_and_wraps():
    atlas = np.zeros((2, 2, 2, 3), dtype=np.uint8)
    atlas[0, 0, 0], atlas[0, 0, 1], atlas[0, 1, 0], atlas[0, 1, 1] = 0, 100, 200, 50  # [material, v, u]
    atlas[1] = 255
    u = np.array([0.5, 1.5, 0.5, 1.0, 1.0, 2.5, 0.0, 0.5, 1.0])
    v = np.array([0.5, 0.5, 1.5, 0.5, 1.0, 0.5, 0.5, 2.5, 1.0])
    material = np.array([0, 0, 0, 0, 0, 0, 0, 0, 1])
    expected = [0, 100, 200, 50, 87.5, 0, 50, 0, 255]  # texel centres at +0.5; 2.5 wraps to 0.5
    got = sample_atlas(atlas, material, u, v)
    np.testing.assert_allclose(got, np.repeat(np.array(expected, float)[:, None], 3, axis=1) / 255.0, atol=1e-6)


def test_contrast_zero_gives_the_plain_base_colour():
    material = Material(name="plain", color=np.array([0.2, 0.4, 0.6]), style="blobs")
    texture = make_texture(material, seed=0, size=16, contrast=0.0)
    assert (texture == np.array([51, 102, 153], dtype=np.uint8)).all()
    assert np.ptp(make_texture(material, seed=0, size=16, contrast=0.3).astype(int)) > 20
