"""Each object's geometry on its own, from LiveScene's interaction probability field (docs/export.md).

The field renders per pixel a probability of each object (``probs``, background last; docs/model.md).
An object's part is fused from the pixels where that probability is high, so exporting the same
object at two states shows it as a moving part next to the static room.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from .tsdf_fusion import FusionSettings, TSDFFusion


def object_pixels(probs: np.ndarray, index: int, threshold: float, erode_px: int = 1) -> np.ndarray:
    """Bool [H, W]: pixels where object ``index`` has probability >= ``threshold``.

    Eroded by ``erode_px``: silhouette pixels mix the object's depth with what lies behind it.
    """
    mask = np.asarray(probs)[..., index] >= threshold
    if erode_px > 0 and mask.any():
        kernel = np.ones((2 * erode_px + 1, 2 * erode_px + 1), np.uint8)
        mask = cv2.erode(mask.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    return mask


class ObjectPartFusion:
    """One TSDF volume per object, fed only that object's pixels."""

    def __init__(self, objects: Sequence[str], box: np.ndarray, settings: FusionSettings,
                 threshold: float = 0.5, erode_px: int = 1) -> None:
        self.objects = list(objects)
        self.threshold = threshold
        self.erode_px = erode_px
        self.parts = {name: TSDFFusion(box, settings) for name in self.objects}

    def integrate(self, camera, c2w: np.ndarray, rgb: np.ndarray, z_depth: np.ndarray, probs: np.ndarray) -> None:
        """``probs`` [H, W, objects + 1] as rendered; ``z_depth`` already filtered (0 = skip)."""
        for j, name in enumerate(self.objects):
            mask = object_pixels(probs, j, self.threshold, self.erode_px)
            if mask.any():
                self.parts[name].integrate(camera, c2w, rgb, np.where(mask, z_depth, 0.0).astype(np.float32))
