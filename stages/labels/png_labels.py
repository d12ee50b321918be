"""PNG id maps: one image per frame, pixel value 0 = background, k = the object whose id is k in the name table.

A palette PNG (mode "P": DAVIS's format, what video object segmenters such as XMem, Cutie and SAM 2's video
predictor write) holds the id as the palette index, read as such (``stages.scene.mask_images``); an alpha
channel (grey + alpha, RGBA) holds no id and is left out.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stages.scene import frame_id_of
from stages.scene.mask_images import colour_channels
from stages.scene.mask_images import read_mask_image as read_stored_mask

from .errors import LabelError
from .label_set import LabelEntry, LabelMap, LabelSet
from .mask_checks import between_and_edge_pixels
from .name_table import NameTable

JPEG_SUFFIXES = (".jpg", ".jpeg")


def png_masks(folder: Path) -> list[Path]:
    """The PNG masks of ``folder`` (``.png`` in any case), sorted; JPEG masks are refused, not skipped."""
    entries = [p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")]  # no macOS ``._`` copies
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
        img = colour_channels(read_mask_image(path))  # an alpha channel (grey + alpha, RGBA) holds no ids
        if img.ndim == 3:
            if not all(np.array_equal(img[..., 0], img[..., c]) for c in range(1, img.shape[2])):
                raise LabelError(path, "id map has colour channels that differ (an RGB image, not ids)",
                                 "save a single-channel (grey) or palette PNG whose values are the object ids")
            img = img[..., 0]
        values = _values(img)
        unknown = [int(v) for v in values if not known[int(v)]]
        if unknown:
            shown = f"{unknown}" if len(unknown) <= 10 else f"{unknown[:10]} and {len(unknown) - 10} more"
            if _between_neighbours(img, known):
                raise LabelError(path, f"pixel values {shown} are no id of {table.path}, and most of their pixels lie "
                                 "on edges between a smaller and a larger value: the id map has anti-aliased edges "
                                 "or was resized with interpolation",
                                 "export the id maps without anti-aliasing (resize them nearest-neighbour); known ids "
                                 f"{list(table.ids)}")
            raise LabelError(path, f"pixel values {shown} are no id of {table.path}",
                             f"add them to the name table or relabel those pixels (known ids {list(table.ids)})")
        if img.dtype == np.uint8:  # OpenCV's table lookup: a tenth of numpy's indexing on a 4K mask
            return LabelMap(cv2.LUT(np.ascontiguousarray(img), lut[:256]))
        return LabelMap(lut[img].astype(np.uint16))

    return load


def _between_neighbours(img: np.ndarray, known: np.ndarray) -> bool:
    """True when at least half of the pixels of unknown value lie between a smaller and a larger value of their 3x3
    window: the ribbons an anti-aliased or interpolated id map has along its edges (docs/labels-states.md)."""
    between, _ = between_and_edge_pixels(img)
    stray = ~known[img]
    return bool(np.count_nonzero(stray & between) >= 0.5 * np.count_nonzero(stray))


def _values(img: np.ndarray) -> np.ndarray:
    """The pixel values of an id map, ascending (``np.unique``); an 8-bit map's from its histogram, which takes
    a fifth of the time on a 4K mask."""
    if img.dtype == np.uint8:
        counts = cv2.calcHist([np.ascontiguousarray(img)], [0], None, [256], [0, 256]).ravel()
        return np.flatnonzero(counts)
    return np.unique(img)


def read_mask_image(path: Path) -> np.ndarray:
    """A mask PNG as stored (``stages.scene.mask_images``): palette indices, or OpenCV's unchanged read."""
    img = read_stored_mask(path)
    if img is None:
        raise LabelError(path, "image missing or unreadable", "re-export the mask as PNG")
    return img
