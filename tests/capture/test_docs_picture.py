"""The docs script that draws a capture frame closed and open keeps working."""

from __future__ import annotations

import runpy
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def test_open_closed_picture_differs_between_halves(tmp_path):
    script = runpy.run_path(str(ROOT / "docs" / "scripts" / "capture_open_closed.py"))
    out = script["open_closed_picture"](ROOT / "config" / "captures" / "tiny.yaml", tmp_path / "pic.png",
                                        frame=10, supersample=1)
    img = cv2.imread(str(out))
    assert img.shape == (2 * 72, 2 * 96, 3)
    closed, opened = img[20:72, :96], img[20:72, 96:]  # below the labels
    assert np.abs(closed.astype(int) - opened.astype(int)).max() > 50
    assert out.stat().st_size < 200 * 1024
