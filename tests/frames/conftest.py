"""Fixtures of the frames tests (the data itself is made in frames_testdata.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
from frames_testdata import SHARP, make_frames, write_video


@pytest.fixture(scope="session")
def blur_video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """20-frame mp4 whose sharp frames are SHARP (all others blurred)."""
    return write_video(tmp_path_factory.mktemp("video") / "walk.mp4", make_frames(20, SHARP))
