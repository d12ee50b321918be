"""PNG id maps: one image per frame, pixel value 0 = background, k = the object whose id is k in the name table.

A palette PNG (mode "P": DAVIS's format, what video object segmenters such as XMem, Cutie and SAM 2's video
predictor write) holds the id as the palette index; OpenCV would decode it into the palette's colours, so it is
read through Pillow, which keeps the indices.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from stages.scene import frame_id_of

from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet
from .name_table import NameTable

JPEG_SUFFIXES = (".jpg", ".jpeg")


def png_masks(folder: Path) -> list[Path]:
    """The PNG masks of ``folder`` (``.png`` in any case), sorted; JPEG masks are refused, not skipped."""
    entries = [p for p in folder.iterdir() if p.is_file()]
    files = sorted(p for p in entries if p.suffix.lower() == ".png")
    jpegs = sorted(p.name for p in entries if p.suffix.lower() in JPEG_SUFFIXES)
    if jpegs:
        named = ", ".join(jpegs[:3]) + (", ..." if len(jpegs) > 3 else "")
        raise LabelError(folder, f"{len(jpegs)} masks are JPEG ({named}): JPEG's compression bleeds mask edges "
                         "into other ids", "export the masks as PNG")
    return files


def read_png_labels(folder: Path, table: NameTable) -> LabelSet:
    if 0 in table.ids:
        raise LabelError(table.path or folder, "id 0 names an object, but 0 is background in a PNG id map",
                         "number the objects from 1 (their pixel values)")
    files = png_masks(folder)
    lut = np.zeros(max(max(table.ids) + 1, 65536), dtype=np.uint16)
    known = np.zeros(lut.size, dtype=bool)
    known[0] = True
    for ident, index in table.index_of_id().items():
        if ident < 0:
            raise LabelError(table.path or folder, f"id {ident} is negative", "use the pixel values 1..255 as ids")
        lut[ident] = index
        known[ident] = True
    entries = [LabelEntry(frame_id_of(f.stem), str(f), _loader(f, lut, known, table)) for f in files]
    return LabelSet("png", table.names, str(table.path), table.ids, entries)


def _loader(path: Path, lut: np.ndarray, known: np.ndarray, table: NameTable):
    def load() -> LabelMap:
        img = read_mask_image(path)
        if img.ndim == 3:
            if not all(np.array_equal(img[..., 0], img[..., c]) for c in range(1, img.shape[2])):
                raise LabelError(path, "id map has colour channels that differ (an RGB image, not ids)",
                                 "save a single-channel (grey) or palette PNG whose values are the object ids")
            img = img[..., 0]
        values = np.unique(img)
        unknown = [int(v) for v in values if not known[int(v)]]
        if unknown:
            raise LabelError(path, f"pixel values {unknown} are no id of {table.path}",
                             f"add them to the name table or relabel those pixels (known ids {list(table.ids)})")
        return LabelMap(lut[img].astype(np.uint16))

    return load


def read_mask_image(path: Path) -> np.ndarray:
    """A mask PNG as stored: a palette PNG's indices [H, W] (Pillow), any other image as OpenCV reads it unchanged."""
    indices = _palette_indices(path)
    img = indices if indices is not None else cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise LabelError(path, "image missing or unreadable", "re-export the mask as PNG")
    return img


def _palette_indices(path: Path) -> np.ndarray | None:
    """The palette indices [H, W] of a palette PNG; None for any other image."""
    try:
        with Image.open(path) as image:
            return np.asarray(image) if image.mode == "P" else None
    except (OSError, ValueError):  # unreadable: OpenCV's read then names the problem
        return None
