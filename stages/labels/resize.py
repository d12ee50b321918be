"""Bring an id map to the frame size by an integer factor (nearest neighbour), or refuse.

Non-integer factors would need resampling that invents or drops object
boundaries unevenly, so they are rejected with a message naming both sizes.
One exception is the frames stage's own downscale (``frames --max-side``): it
divides both sides by one integer and rounds (4032x3024 / 5 -> 806x605), so a
mask at the source's full size is sampled under each frame pixel's centre,
through the same mapping the frame's resize used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .errors import LabelError


def resize_factor(src_hw: tuple[int, int], dst_hw: tuple[int, int]) -> tuple[str, int]:
    """``("up" | "down" | "same", k)`` for an integer factor shared by both axes, or ``("down", k)`` for the
    frames stage's rounded downscale by ``k``; ValueError otherwise."""
    (sh, sw), (dh, dw) = src_hw, dst_hw
    if (sh, sw) == (dh, dw):
        return "same", 1
    if dh % sh == 0 and dw % sw == 0 and dh // sh == dw // sw:
        return "up", dh // sh
    if sh % dh == 0 and sw % dw == 0 and sh // dh == sw // dw:
        return "down", sh // dh
    k = round(max(sh, sw) / max(dh, dw))
    if k >= 2 and (max(1, round(sh / k)), max(1, round(sw / k))) == (dh, dw):  # frames.selection.scaled_size
        return "down", k
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
        # the source pixel under each target pixel's centre; for an exact factor, rows k // 2, k // 2 + k, ...
        (sh, sw), (dh, dw) = labels.shape[:2], dst_hw
        rows = np.minimum(((np.arange(dh) + 0.5) * sh / dh).astype(np.int64), sh - 1)
        cols = np.minimum(((np.arange(dw) + 0.5) * sw / dw).astype(np.int64), sw - 1)
        return np.ascontiguousarray(labels[rows[:, None], cols[None, :]])
    return labels
