"""A label set in any source format, seen as per-frame id maps over canonical object indices.

Every reader turns its format into the same thing: for each labelled frame a
``uint16`` map at the annotation's own resolution where 0 is background and
``k`` is the k-th object of the canonical order (1-based). Everything after
that (matching to frames, resizing, one-hot masks, coverage) is shared.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class LabelMap:
    """One frame's labels at the annotation resolution."""

    labels: np.ndarray
    """``uint16 [h, w]``: 0 background, k = canonical object k (1-based)."""
    overlap_pixels: int = 0
    """Pixels claimed by more than one object (the later object in canonical order keeps them)."""


@dataclass(frozen=True)
class LabelEntry:
    """A labelled frame of the source, loaded on demand."""

    label_id: str
    """Frame id as the source names it (may differ in zero padding from the frames)."""
    source: str
    """Where it comes from (file, or file and image entry), for messages."""
    load: Callable[[], LabelMap]
    """Reads and rasterises the labels."""


@dataclass
class LabelSet:
    """All labelled frames of one source and the names of its objects."""

    format: str
    """npy, png, coco, labelme or objects (one folder per object)."""
    names: tuple[str, ...]
    """Object names in canonical order."""
    names_from: str
    """The file (or rule) the names and their order came from."""
    source_ids: tuple[int, ...] = ()
    """The source's own ids for the objects (pixel values, class or category ids), when it has them."""
    entries: list[LabelEntry] = field(default_factory=list)


def paint(canvas: np.ndarray, region: np.ndarray, index: int) -> int:
    """Paint object ``index`` over ``region``; return how many pixels another object already held."""
    clash = int(np.count_nonzero(region & (canvas != 0) & (canvas != index)))
    canvas[region] = index
    return clash
