"""Sharpness score of a frame: variance of the Laplacian of its grey image.

Motion blur removes high frequencies, and the Laplacian responds only to
them, so a blurred frame has a small Laplacian variance. The score is
comparable between frames of one video (same size, same content scale),
which is all that choosing the sharpest frame of a window needs.
"""

from __future__ import annotations

import cv2
import numpy as np


def laplacian_variance(image: np.ndarray) -> float:
    """Variance of the Laplacian of ``image`` (BGR or grey, uint8)."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    return float(cv2.Laplacian(grey, cv2.CV_64F).var())
