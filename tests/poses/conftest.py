"""Fixtures of the pose tests (the rendered room itself is in poses_testdata.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from poses_testdata import SMALL_CAMERA, orbit_poses, write_sequence

from stages.scene import Camera


@pytest.fixture(scope="session")
def room_sequence(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Camera, list[np.ndarray]]:
    """12 rendered 160x120 frames on an arc (FRAMES-like folder), their id masks, camera and true poses."""
    root = tmp_path_factory.mktemp("room")
    poses = orbit_poses(12)
    _images, masks, camera = write_sequence(root, poses, SMALL_CAMERA)
    return root, masks, camera, poses
