"""Polygon rasterisation shared by the COCO and LabelMe readers.

Vertices are read as pixel coordinates (x right, y down, pixel (0, 0) at
(0, 0)) and filled inclusively with OpenCV, the convention of LabelMe's own
mask export; polygons traced along pixel centres (``cv2.findContours``)
therefore fill back to exactly the traced pixels. pycocotools centres pixels at
+0.5 instead, which can differ by up to one pixel along an edge.
"""

from __future__ import annotations

import cv2
import numpy as np

SUBPIXEL_BITS = 4  # OpenCV fixed-point shift: vertices keep 1/16 pixel precision


def fill_polygons(polygons: list[np.ndarray], height: int, width: int) -> np.ndarray:
    """Union of filled polygons (each ``[n, 2]`` x, y) -> bool mask ``[height, width]``."""
    canvas = np.zeros((height, width), dtype=np.uint8)
    scale = 1 << SUBPIXEL_BITS
    pts = [np.round(np.asarray(p, dtype=np.float64) * scale).astype(np.int32).reshape(-1, 1, 2) for p in polygons]
    if pts:
        cv2.fillPoly(canvas, pts, 1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
    return canvas.astype(bool)


def polygon_from_flat(values: list[float]) -> np.ndarray:
    """COCO ``[x1, y1, x2, y2, ...]`` -> ``[n, 2]``; raises ValueError when it is no polygon."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1 or arr.size < 6 or arr.size % 2:
        raise ValueError(f"a polygon needs an even number (>= 6) of coordinates, got {arr.size}")
    if not np.isfinite(arr).all():
        raise ValueError("polygon has NaN or infinite coordinates")
    return arr.reshape(-1, 2)
