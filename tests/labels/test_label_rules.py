"""Ingestion rules worked out by hand on masks of a few pixels: overlaps, the name table's order, resizing, COCO's
compressed RLE, a frame labelled twice."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from labelset_writers import write_png

from stages.labels import LabelError, LabelsConfig, decode_rle, ingest_labels
from stages.labels.coco_labels import read_coco_labels
from stages.labels.coco_rle import decode_counts_string
from stages.labels.labelme_labels import read_labelme_labels
from stages.labels.name_table import read_name_table
from stages.labels.resize import resize_factor, resize_labels

# 4 x 6 pixels; polygons are filled inclusively (stages/labels/polygon_fill.py): x 0..5, y 0..3 is every pixel
EVERY_PIXEL = [0, 0, 5, 0, 5, 3, 0, 3]
LEFT_TWO_COLUMNS = [0, 0, 1, 0, 1, 3, 0, 3]  # 8 pixels


def _coco(path: Path, annotations: list[tuple[int, list[float]]]) -> Path:
    doc = {"images": [{"id": 1, "file_name": "frame_00000.png", "height": 4, "width": 6}],
           "categories": [{"id": 1, "name": "door"}, {"id": 2, "name": "drawer"}],
           "annotations": [{"id": i, "image_id": 1, "category_id": cat, "segmentation": [polygon]}
                           for i, (cat, polygon) in enumerate(annotations)]}
    path.write_text(json.dumps(doc))
    return path


def _labelme(path: Path, shapes: list[tuple[str, list[float]]]) -> Path:
    doc = {"shapes": [{"label": label, "points": np.reshape(polygon, (-1, 2)).tolist(), "shape_type": "polygon"}
                      for label, polygon in shapes],
           "imageHeight": 4, "imageWidth": 6}
    path.write_text(json.dumps(doc))
    return path


def test_a_contested_pixel_goes_to_the_later_object_whatever_the_file_order(tmp_path: Path) -> None:
    """door = object 1, drawer = object 2. The drawer covers the image and comes first in the file, the door covers
    the two left columns: the later object in canonical order (the drawer) keeps all 8 contested pixels, in COCO
    and LabelMe alike (as the npy reader's "last channel wins")."""
    coco = read_coco_labels(_coco(tmp_path / "coco.json", [(2, EVERY_PIXEL), (1, LEFT_TWO_COLUMNS)]), None)
    labelme = read_labelme_labels([_labelme(tmp_path / "0.json", [("drawer", EVERY_PIXEL),
                                                                  ("door", LEFT_TWO_COLUMNS)])], None)
    for label_set in (coco, labelme):
        assert label_set.names == ("door", "drawer")
        result = label_set.entries[0].load()
        np.testing.assert_array_equal(result.labels, np.full((4, 6), 2), err_msg=label_set.format)
        assert result.overlap_pixels == 8, label_set.format


def test_two_polygons_of_one_object_are_no_overlap(tmp_path: Path) -> None:
    """A door drawn in two overlapping pieces (x 0..3 and x 2..5): its union, and no pixel claimed by two objects."""
    coco = read_coco_labels(_coco(tmp_path / "coco.json", [(1, [0, 0, 3, 0, 3, 3, 0, 3]),
                                                           (1, [2, 0, 5, 0, 5, 3, 2, 3])]), None)
    labelme = read_labelme_labels([_labelme(tmp_path / "0.json", [("door", [0, 0, 3, 0, 3, 3, 0, 3]),
                                                                  ("door", [2, 0, 5, 0, 5, 3, 2, 3])])], None)
    for label_set in (coco, labelme):
        result = label_set.entries[0].load()
        np.testing.assert_array_equal(result.labels, np.ones((4, 6)), err_msg=label_set.format)
        assert result.overlap_pixels == 0, label_set.format


def test_the_name_table_orders_objects_by_id_not_by_line(tmp_path: Path) -> None:
    path = tmp_path / "mapping.yaml"
    path.write_text("7: fridge\n3: door\n5: drawer\n")
    table = read_name_table(path)
    assert table.ids == (3, 5, 7) and table.names == ("door", "drawer", "fridge")
    assert table.index_of_id() == {3: 1, 5: 2, 7: 3}


def test_a_size_scaled_differently_per_axis_is_refused() -> None:
    """24 x 32 -> 48 x 96 doubles the height but triples the width: no integer factor shared by both axes."""
    with pytest.raises(ValueError, match="no integer factor"):
        resize_factor((24, 32), (48, 96))
    with pytest.raises(LabelError, match="mask size cannot be matched"):
        resize_labels(np.zeros((24, 32), np.uint16), (48, 96), "mask.png")
    assert resize_factor((24, 32), (72, 96)) == ("up", 3)


def test_an_exact_downscale_samples_the_pixel_under_each_centre() -> None:
    """6 x 6 -> 2 x 2 (factor 3): target pixel 0 covers source pixels 0..2, centre 1; target 1 covers 3..5,
    centre 4."""
    source = np.arange(36, dtype=np.uint16).reshape(6, 6)
    np.testing.assert_array_equal(resize_labels(source, (2, 2), "mask.png"), [[7, 10], [25, 28]])


def test_compressed_rle_from_the_format_description() -> None:
    """COCO's string form, encoded by hand: 5 bits per character (offset 48), bit 0x20 "more follows", bit 0x10 of
    the last group the sign; from the fourth count on, the difference to the count two places back.
    Counts [1, 3, 1, 1]: '1', '3', '1', then 1 - 3 = -2 = 0b11110 -> chr(30 + 48) = 'N'.
    Column-major over a 2 x 3 mask, zeros first: 0 | 1 1 1 | 0 | 1."""
    assert decode_counts_string("131N") == [1, 3, 1, 1]
    np.testing.assert_array_equal(decode_rle("131N", 2, 3), [[False, True, False], [True, True, True]])
    assert decode_counts_string("X1") == [40]  # 40 = 8 + 1 * 32: 'X' (8 | 0x20 "more"), then '1'


def test_a_frame_labelled_twice_is_refused(label_files) -> None:
    """frame_00000.png and img0.png both name frame 00000: neither may silently replace the other."""
    src = write_png(label_files.root, label_files.labels)
    shutil.copyfile(src / "masks" / "frame_00000.png", src / "masks" / "img0.png")
    out = label_files.root / "out"
    with pytest.raises(LabelError, match=r"frame 00000 is labelled twice \(also by .*frame_00000\.png\)"):
        ingest_labels(LabelsConfig(input=src, frames=label_files.frames, out=out, progress=False,
                                   missing_masks="leave"))
    assert not out.exists()


def test_an_id_map_whose_red_channel_alone_differs_is_refused(tmp_path: Path) -> None:
    """Blue and green equal, red not (cv2 writes B, G, R): colours, not one id per pixel."""
    import cv2

    from stages.labels.name_table import NameTable
    from stages.labels.png_labels import read_png_labels

    ids = np.zeros((4, 6), np.uint8)
    ids[:, :3] = 3
    assert cv2.imwrite(str(tmp_path / "frame_00000.png"), np.dstack([ids, ids, ids // 3]))
    label_set = read_png_labels(tmp_path, NameTable(ids=(3,), names=("door",), path=None))
    with pytest.raises(LabelError, match="id map has colour channels that differ"):
        label_set.entries[0].load()


def test_an_8_bit_and_a_16_bit_id_map_read_alike(tmp_path: Path) -> None:
    """The 8-bit reading (histogram, table lookup) gives the ids, and names the unknown values, as the 16-bit one
    (numpy) does: ids 7 and 200 (out of order in the name table), 0 background, 255 unknown."""
    import cv2

    from stages.labels.name_table import NameTable
    from stages.labels.png_labels import read_png_labels

    ids = np.array([[0, 200, 7], [7, 0, 200]], np.uint8)
    table = NameTable(ids=(200, 7), names=("door", "drawer"), path=tmp_path / "mapping.yaml")
    for depth, folder in ((np.uint8, tmp_path / "a"), (np.uint16, tmp_path / "b")):
        folder.mkdir()
        assert cv2.imwrite(str(folder / "frame_00000.png"), ids.astype(depth))
        bad = ids.astype(depth)
        bad[1, 1] = 255
        assert cv2.imwrite(str(folder / "frame_00001.png"), bad)
    maps = []
    for folder in (tmp_path / "a", tmp_path / "b"):
        entries = read_png_labels(folder, table).entries
        labels = entries[0].load().labels
        assert labels.dtype == np.uint16
        maps.append(labels)
        with pytest.raises(LabelError, match=r"pixel values \[255\] are no id"):
            entries[1].load()
    assert np.array_equal(maps[0], [[0, 1, 2], [2, 0, 1]]) and np.array_equal(maps[0], maps[1])
