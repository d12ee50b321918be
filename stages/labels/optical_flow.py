"""Dense optical flow between neighbouring frames (OpenCV DIS), computed on demand and cached per pair.

Mask propagation (docs/labels-states.md, "Masks on key frames only") chains flows of *neighbouring*
frames: small displacements are what DIS handles best, and chaining lets the occlusion check run at
every step. Frames larger than ``max_side`` are downscaled for the flow, and the flows are kept at that
size (sampled at scaled positions by ``sample``), so the flows of a 4K phone video cost what a 1080p
one's do, in time and memory. Each flow is computed once; the propagation releases it after use, parking
it in a scratch folder (``spill``) when its second pass over the segment will need it again.
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
    """Flows between frames ``i`` and ``i +/- 1`` of an image list, held until ``release``d (then dropped, or parked
    in ``spill`` and read back by the next ``flow``)."""

    def __init__(self, images: Sequence[Path], shape: tuple[int, int], max_side: int = FLOW_MAX_SIDE,
                 spill: Path | None = None) -> None:
        self.images = list(images)
        self.shape = shape
        h, w = shape
        self.scale = min(1.0, max_side / max(h, w))
        self._small = (max(1, round(w * self.scale)), max(1, round(h * self.scale)))
        # MEDIUM: the preset OpenCV recommends for accuracy at interactive speed (a few ms at 256x192)
        self._dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        self._grey: dict[int, np.ndarray] = {}
        self._flow: dict[tuple[int, int], np.ndarray] = {}
        self._spill = spill
        self.computed = 0
        """Number of flows computed (for the timing report)."""

    def grey(self, i: int) -> np.ndarray:
        if i not in self._grey:
            img = read_grey(self.images[i], self.shape)
            if self.scale < 1.0:
                img = cv2.resize(img, self._small, interpolation=cv2.INTER_AREA)
            if len(self._grey) >= 3:  # a flow needs two frames; the walks move one frame at a time
                self._grey.pop(next(iter(self._grey)))
            self._grey[i] = img
        return self._grey[i]

    def _parked(self, i: int, j: int) -> Path | None:
        return None if self._spill is None else self._spill / f"flow_{i}_{j}.npy"

    def flow(self, i: int, j: int) -> np.ndarray:
        """float32 ``h x w x 2`` (dx, dy) at the flow resolution: pixel ``p`` of frame i (flow pixels) is seen
        at ``p + flow(p)`` in frame j."""
        if abs(i - j) != 1:
            raise ValueError(f"flows are between neighbouring frames only, not {i} -> {j}")
        key = (i, j)
        if key not in self._flow:
            parked = self._parked(i, j)
            if parked is not None and parked.is_file():
                self._flow[key] = np.load(parked)
            else:
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

    def release(self, i: int, j: int, keep: bool = False) -> None:
        """Free the flows i -> j and j -> i from memory; ``keep`` parks them in ``spill`` for one more use,
        otherwise a parked copy is deleted too."""
        for key in ((i, j), (j, i)):
            flow = self._flow.pop(key, None)
            parked = self._parked(*key)
            if keep:
                if parked is None:
                    raise ValueError("FrameFlows was made without a spill folder: nothing can be kept")
                if flow is not None and not parked.is_file():
                    np.save(parked, flow)
            elif parked is not None:
                parked.unlink(missing_ok=True)
