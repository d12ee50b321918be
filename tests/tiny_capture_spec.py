"""The tiny capture preset made smaller still, for the tests that render captures (capture, export)."""

from __future__ import annotations

from pathlib import Path

from stages.capture import CaptureSpec, load_spec

PRESETS = Path(__file__).resolve().parents[1] / "config" / "captures"


def small_spec(n_frames: int = 8, width: int = 64, height: int = 48) -> CaptureSpec:
    """config/captures/tiny.yaml with fewer frames, a smaller video, smaller textures and no supersampling."""
    spec = load_spec(PRESETS / "tiny.yaml")
    spec.video.n_frames = n_frames
    spec.video.width, spec.video.height = width, height
    spec.render.texture_size = 64
    spec.render.supersample = 1
    return spec
