"""Images for the page: data URIs (so the page is one file) and error maps."""

from __future__ import annotations

import base64
from pathlib import Path

import numpy as np


def read_rgb(path: str | Path) -> np.ndarray | None:
    """An image as uint8 RGB, or None when it is missing or unreadable."""
    import cv2

    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    return None if image is None else image[..., ::-1].copy()


def png_data_uri(rgb: np.ndarray) -> str:
    """Encode an RGB (or grey) uint8 image as a PNG data URI."""
    import cv2

    array = rgb[..., ::-1] if rgb.ndim == 3 else rgb
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(array))
    if not ok:
        raise ValueError("PNG encoding failed")
    return "data:image/png;base64," + base64.b64encode(buf.tobytes()).decode("ascii")


def file_data_uri(path: str | Path) -> str | None:
    """A PNG/JPEG file as a data URI (bytes copied as they are), or None when absent."""
    path = Path(path)
    if not path.is_file():
        return None
    kind = "jpeg" if path.suffix.lower() in (".jpg", ".jpeg") else "png"
    return f"data:image/{kind};base64," + base64.b64encode(path.read_bytes()).decode("ascii")


def error_map(truth: np.ndarray, render: np.ndarray, max_error: float = 0.25) -> np.ndarray:
    """Per-pixel mean absolute error as an inferno-coloured RGB image (black 0 .. yellow >= max_error)."""
    import cv2

    if render.shape[:2] != truth.shape[:2]:
        render = cv2.resize(render, (truth.shape[1], truth.shape[0]), interpolation=cv2.INTER_AREA)
    err = np.abs(truth.astype(np.float32) - render.astype(np.float32)).mean(axis=-1) / 255.0
    scaled = np.clip(err / max_error * 255.0, 0, 255).astype(np.uint8)
    return cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO)[..., ::-1].copy()
