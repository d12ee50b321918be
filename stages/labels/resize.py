"""Bring an id map to the frame size by an integer factor (nearest neighbour), or refuse.

Non-integer factors would need resampling that invents or drops object
boundaries unevenly, so they are rejected with a message naming both sizes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import LabelError


def resize_factor(src_hw: tuple[int, int], dst_hw: tuple[int, int]) -> tuple[str, int]:
    """``("up" | "down" | "same", k)`` for an integer factor shared by both axes; ValueError otherwise."""
    (sh, sw), (dh, dw) = src_hw, dst_hw
    if (sh, sw) == (dh, dw):
        return "same", 1
    if dh % sh == 0 and dw % sw == 0 and dh // sh == dw // sw:
        return "up", dh // sh
    if sh % dh == 0 and sw % dw == 0 and sh // dh == sw // dw:
        return "down", sh // dh
    raise ValueError(f"{sw}x{sh} -> {dw}x{dh} is no integer factor shared by width and height")


def resize_labels(labels: np.ndarray, dst_hw: tuple[int, int], source: str | Path) -> np.ndarray:
    """Nearest-neighbour resize of an id map by an integer factor."""
    try:
        kind, k = resize_factor(labels.shape[:2], dst_hw)
    except ValueError as exc:
        raise LabelError(source, f"mask size cannot be matched to the frames ({exc})",
                         "export the masks at the frame size or at an integer fraction/multiple of it") from exc
    if kind == "up":
        return np.repeat(np.repeat(labels, k, axis=0), k, axis=1)
    if kind == "down":
        # sample the source pixel under each target pixel's centre
        return np.ascontiguousarray(labels[k // 2::k, k // 2::k])
    return labels
