"""Dense optical flow between neighbouring frames (OpenCV DIS), computed on demand and cached per pair.

Mask propagation (docs/labels-states.md, "Masks on key frames only") chains flows of *neighbouring*
frames: small displacements are what DIS handles best, and chaining lets the occlusion check run at
every step. Frames larger than ``max_side`` are downscaled for the flow, and the flows are kept at that
size (sampled at scaled positions by ``sample``), so the flows of a 4K phone video cost what a 1080p
one's do, in time and memory.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from .errors import LabelError

FLOW_MAX_SIDE = 1024
"""Longest image side the flow is computed at; larger frames are downscaled for the flow."""


def read_grey(path: Path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """A frame as uint8 grey; unreadable files and frames of another size name the file."""
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise LabelError(path, "image missing or unreadable, so masks cannot be propagated over it",
                         "re-extract the frames with `livescene frames`, or annotate every frame "
                         "(--missing-masks leave skips propagation)")
    if shape is not None and img.shape[:2] != shape:
        raise LabelError(path, f"frame is {img.shape[1]}x{img.shape[0]} but the first frame is {shape[1]}x{shape[0]}",
                         "extract every frame at one size (`livescene frames`)")
    return img


class FrameFlows:
    """Flows between frames ``i`` and ``i +/- 1`` of an image list, cached until ``forget_before``."""

    def __init__(self, images: Sequence[Path], shape: tuple[int, int], max_side: int = FLOW_MAX_SIDE) -> None:
        self.images = list(images)
        self.shape = shape
        h, w = shape
        self.scale = min(1.0, max_side / max(h, w))
        self._small = (max(1, round(w * self.scale)), max(1, round(h * self.scale)))
        # MEDIUM: the preset OpenCV recommends for accuracy at interactive speed (a few ms at 256x192)
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        self._grey: dict[int, np.ndarray] = {}
        self._flow: dict[tuple[int, int], np.ndarray] = {}
        self.computed = 0
        """Number of flows computed (for the timing report)."""

    def grey(self, i: int) -> np.ndarray:
        if i not in self._grey:
            img = read_grey(self.images[i], self.shape)
            if self.scale < 1.0:
                img = cv2.resize(img, self._small, interpolation=cv2.INTER_AREA)
            self._grey[i] = img
        return self._grey[i]

    def flow(self, i: int, j: int) -> np.ndarray:
        """float32 ``h x w x 2`` (dx, dy) at the flow resolution: pixel ``p`` of frame i (flow pixels) is seen
        at ``p + flow(p)`` in frame j."""
        if abs(i - j) != 1:
            raise ValueError(f"flows are between neighbouring frames only, not {i} -> {j}")
        key = (i, j)
        if key not in self._flow:
            f = self._dis.calc(self.grey(i), self.grey(j), None)
            self._flow[key] = np.ascontiguousarray(f, dtype=np.float32)
            self.computed += 1
        return self._flow[key]

    def sample(self, i: int, j: int, pos: np.ndarray) -> np.ndarray:
        """The flow i -> j in frame pixels at ``pos`` (``H x W x 2`` float32 x, y in frame pixels), bilinear."""
        f = self.flow(i, j)
        if self.scale == 1.0:
            return cv2.remap(f, pos[..., 0], pos[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        # pixel centres: x_small = (x + 0.5) * scale - 0.5
        xs = (pos[..., 0] + 0.5) * self.scale - 0.5
        ys = (pos[..., 1] + 0.5) * self.scale - 0.5
        return cv2.remap(f, xs, ys, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) / self.scale

    def forget_before(self, index: int) -> None:
        """Drop cached images and flows of frames before ``index`` (memory stays bounded on long videos)."""
        self._flow = {k: v for k, v in self._flow.items() if min(k) >= index}
        self._grey = {k: v for k, v in self._grey.items() if k >= index}
