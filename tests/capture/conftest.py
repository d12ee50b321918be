"""Tiny captures generated at test time (a few seconds), shared across the capture tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from stages.capture import CaptureSpec, generate_capture, load_spec

ROOT = Path(__file__).resolve().parents[2]
PRESETS = ROOT / "config" / "captures"


def small_spec(n_frames: int = 8, width: int = 64, height: int = 48) -> CaptureSpec:
    """The tiny preset, made smaller still: fewer frames, smaller textures, no supersampling."""
    spec = load_spec(PRESETS / "tiny.yaml")
    spec.video.n_frames = n_frames
    spec.video.width, spec.video.height = width, height
    spec.render.texture_size = 64
    spec.render.supersample = 1
    return spec


@pytest.fixture(name="small_spec")
def small_spec_fixture():
    """The ``small_spec`` factory, for tests that need their own spec."""
    return small_spec


@pytest.fixture(scope="session")
def tiny_capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("capture") / "tiny"
    return generate_capture(small_spec(), out, progress=False)
