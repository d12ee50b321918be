"""Mask images as users' tools write them: palette PNGs, grey or colour, with or without an alpha channel.

One reading for every stage that takes masks (labels, the poses stage's feature masks), so a file means the same
object pixels everywhere: a palette PNG (DAVIS's format, what video object segmenters write) holds ids as palette
indices, which OpenCV would decode into the palette's colours, so it is read through Pillow; an alpha channel is
never an id, and in a one-object mask that uses transparency (a cut-out: the object opaque on a transparent
background, what "remove background" exports write) the alpha channel is the mask.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from PIL import Image


def read_mask_image(path: Path) -> np.ndarray | None:
    """A mask image as stored: a palette PNG's indices [H, W], any other image as OpenCV reads it unchanged
    ([H, W] or [H, W, C], C = 3 or 4 with alpha last); None when unreadable."""
    try:
        with Image.open(path) as image:
            if image.mode == "P":
                return np.asarray(image)
    except (OSError, ValueError):  # not an image Pillow reads: OpenCV's read then decides
        pass
    return cv2.imread(str(path), cv2.IMREAD_UNCHANGED)


def colour_channels(img: np.ndarray) -> np.ndarray:
    """The image without its alpha channel ([H, W] stays as it is; [H, W, 4] -> [H, W, 3])."""
    return img[..., :3] if img.ndim == 3 and img.shape[2] == 4 else img


def uses_transparency(img: np.ndarray) -> bool:
    """Whether an alpha channel makes any pixel less than opaque (a cut-out of an object out of view is all
    transparent)."""
    if img.ndim != 3 or img.shape[2] != 4:
        return False
    opaque = np.iinfo(img.dtype).max if img.dtype.kind in "ui" else 1.0
    return bool(img[..., 3].min() < opaque)


def object_region(img: np.ndarray) -> np.ndarray:
    """Bool [H, W] of a one-object mask: with transparency, its opaque pixels (the alpha is the mask, whatever the
    colours: a cut-out keeps the photo's); otherwise any non-zero value in any colour channel."""
    if uses_transparency(img):
        return img[..., 3] > 0
    colour = colour_channels(img)
    return (colour != 0).any(axis=-1) if colour.ndim == 3 else colour != 0
