"""The poses stage's feature masks read mask files as the labels stage does: palette indices, no alpha, numbers."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from stages.poses.colmap_masks import index_masks, object_pixels, write_colmap_masks


def _ids() -> np.ndarray:
    ids = np.zeros((12, 16), np.uint8)
    ids[2:6, 3:8] = 1
    ids[7:10, 9:14] = 2
    return ids


def test_a_palette_id_map_is_read_by_its_indices_whatever_its_colours(tmp_path: Path):
    ids = _ids()
    image = Image.fromarray(ids, mode="P")
    image.putpalette([255, 255, 255, 128, 0, 0, 0, 128, 0] + [0] * 759)  # index 0 (static) drawn white
    image.save(tmp_path / "frame_00000.png")
    np.testing.assert_array_equal(object_pixels(tmp_path / "frame_00000.png"), ids != 0)


def test_an_alpha_channel_is_no_object(tmp_path: Path):
    ids = _ids()
    cv2.imwrite(str(tmp_path / "a.png"), np.dstack([ids, ids, ids, np.full_like(ids, 255)]))  # grey + opaque alpha
    np.testing.assert_array_equal(object_pixels(tmp_path / "a.png"), ids != 0)


def test_masks_pair_with_frames_by_number_and_hidden_files_are_left_out(tmp_path: Path):
    images, masks = tmp_path / "images", tmp_path / "masks"
    images.mkdir()
    masks.mkdir()
    ids = _ids()
    names = [f"frame_{i:05d}.png" for i in (4, 12)]
    for name in names:
        cv2.imwrite(str(images / name), np.full((12, 16, 3), 90, np.uint8))
    cv2.imwrite(str(masks / "IMG_4.png"), ids)  # another tool's naming of frame 4
    cv2.imwrite(str(masks / "img12.png"), ids)
    (masks / "._IMG_4.png").write_bytes(b"Mac OS X        ")
    assert sorted(index_masks(masks)) == ["12", "4"]
    stats = write_colmap_masks(images, names, masks, tmp_path / "out", dilate_px=0)
    assert stats.frames_with_masks == 2 and stats.frames_without_masks == []
    keep = cv2.imread(str(tmp_path / "out" / f"{names[0]}.png"), cv2.IMREAD_GRAYSCALE)
    np.testing.assert_array_equal(keep == 0, ids != 0)
