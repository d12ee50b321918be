"""Fixtures of the labels tests: a FRAMES folder and the label maps of one tiny 3-object label set, and the
synthetic `tiny` capture (video, truth masks) with its extracted frames, generated once per session."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest
from labelset_writers import LabelSetFiles, make_label_maps, write_frames

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def label_files(tmp_path: Path) -> LabelSetFiles:
    labels = make_label_maps()
    return LabelSetFiles(frames=write_frames(tmp_path), labels=labels, root=tmp_path)


@dataclass(frozen=True)
class TinyCapture:
    capture: Path
    """`livescene capture` output of config/captures/tiny.yaml: masks/frame_*.png are the truth masks."""
    frames: Path
    """`livescene frames` of its video.mp4 (30 frames, 96x72)."""


@pytest.fixture(scope="session")
def tiny_capture_frames(tmp_path_factory: pytest.TempPathFactory) -> TinyCapture:
    from stages.capture import generate_capture, load_spec
    from stages.frames.cli import main as frames_main

    root = tmp_path_factory.mktemp("labels_tiny")
    capture = generate_capture(load_spec(ROOT / "config" / "captures" / "tiny.yaml"), root / "capture", progress=False)
    frames = root / "frames"
    assert frames_main(["--video", str(Path(capture) / "video.mp4"), "--out", str(frames), "--no-progress"]) == 0
    return TinyCapture(capture=Path(capture), frames=frames)
