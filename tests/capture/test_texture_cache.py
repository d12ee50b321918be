"""The capture's cached texture atlas: used only when it matches the spec, a cache miss otherwise."""

from __future__ import annotations

import logging
import shutil
from dataclasses import replace

import numpy as np

from stages.capture.renderer import ATLAS_FILE, TruthRenderer
from stages.capture.textures import cached_atlas, texture_atlas


def test_capture_writes_the_atlas_its_truth_renderer_reloads(tiny_capture, monkeypatch):
    assert (tiny_capture / "truth" / ATLAS_FILE).is_file()
    calls = []
    monkeypatch.setattr("stages.capture.textures.texture_atlas",
                        lambda *a: calls.append(a) or texture_atlas(*a))
    renderer = TruthRenderer.from_capture(tiny_capture)
    assert calls == [], "the truth renderer regenerated textures the capture had cached"
    spec, r = renderer.spec, renderer.spec.render
    regenerated = texture_atlas(renderer.model.materials, spec.seed, r.texture_size, r.contrast)
    assert np.array_equal(renderer.atlas, regenerated)


def test_a_stale_or_broken_atlas_is_regenerated(tiny_capture, tmp_path, caplog):
    renderer = TruthRenderer.from_capture(tiny_capture)
    materials, spec, r = renderer.model.materials, renderer.spec, renderer.spec.render
    cached = tiny_capture / "truth" / ATLAS_FILE
    # other inputs (contrast, seed, a material's colour) than the file was written for: not its atlas
    for args in [(materials, spec.seed, r.texture_size, r.contrast + 0.1),
                 (materials, spec.seed + 1, r.texture_size, r.contrast),
                 ([replace(materials[0], color=materials[0].color * 0.5), *materials[1:]], spec.seed, r.texture_size,
                  r.contrast)]:
        assert np.array_equal(cached_atlas(cached, *args), texture_atlas(*args))
        assert not np.array_equal(cached_atlas(cached, *args), renderer.atlas)
    broken = tmp_path / ATLAS_FILE
    broken.write_bytes(b"not an npz")
    with caplog.at_level(logging.WARNING):
        atlas = cached_atlas(broken, materials, spec.seed, r.texture_size, r.contrast)
    assert np.array_equal(atlas, renderer.atlas)
    assert "unreadable" in caplog.text and str(broken) in caplog.text
    assert broken.read_bytes() == b"not an npz", "a broken cache file must be left as it is"


def test_a_capture_without_the_atlas_still_renders(tiny_capture, tmp_path):
    old = tmp_path / "old"
    shutil.copytree(tiny_capture, old)
    (old / "truth" / ATLAS_FILE).unlink()
    a = TruthRenderer.from_capture(old)
    b = TruthRenderer.from_capture(tiny_capture)
    assert np.array_equal(a.atlas, b.atlas)
