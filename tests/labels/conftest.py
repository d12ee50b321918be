"""Fixtures of the labels tests: a FRAMES folder and the label maps of one tiny 3-object label set."""

from __future__ import annotations

from pathlib import Path

import pytest
from labelset_writers import LabelSetFiles, make_label_maps, write_frames


@pytest.fixture
def label_files(tmp_path: Path) -> LabelSetFiles:
    labels = make_label_maps()
    return LabelSetFiles(frames=write_frames(tmp_path), labels=labels, root=tmp_path)
