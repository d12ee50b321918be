"""Frames of a camera panning over a smooth texture, each with its own exposure: data whose gains are known."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stages.scene import SceneDataset, read_scene
from stages.scene.masks import label_map_to_onehot, write_mask
from tests.conftest import make_tiny_dataset


def texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """A smooth RGB texture in [0.15, 0.85] (blurred noise), larger than the frames cut from it."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.random((h, w, 3)).astype(np.float32), (0, 0), 3.0)
    img = (img - img.min()) / (img.max() - img.min())
    return 0.15 + 0.7 * img


def pan(n: int, log_gains: np.ndarray, h: int = 96, w: int = 128, step: int = 1) -> list[np.ndarray]:
    """``n`` frames of a camera panning over a texture, each scaled by its gains and stored in 8 bits."""
    tex = texture(h + 8, w + step * n + 8)
    frames = []
    for i in range(n):
        crop = tex[4:4 + h, 4 + step * i:4 + step * i + w] * np.exp(log_gains[i])
        frames.append(np.round(np.clip(crop, 0, 1) * 255) / 255.0)
    return frames


def write_pan_dataset(root: Path, log_gains: np.ndarray, frames: list[np.ndarray] | None = None,
                      object_columns: tuple[int, int] | None = None) -> SceneDataset:
    """A tiny dataset whose images are a panning camera's frames with the given gains (playback = source order).

    ``frames``: images to write instead of ``pan``'s; ``object_columns``: texture columns [c0, c1) that hold
    object 0 in every frame's mask (the rest is background; by default all of it: a pan over a wall)."""
    ds = make_tiny_dataset(root, n_frames=len(log_gains), width=128, height=96)
    frames = pan(len(log_gains), log_gains) if frames is None else frames
    for i, (frame, img) in enumerate(zip(ds.frames, frames, strict=True)):
        cv2.imwrite(str(ds.image_path(frame)), np.round(img[..., ::-1] * 255).astype(np.uint8))
        labels = np.full((96, 128), ds.n_objects)
        if object_columns is not None:  # pan's frame i shows texture columns from 4 + i on
            labels[:, max(object_columns[0] - 4 - i, 0):max(object_columns[1] - 4 - i, 0)] = 0
        write_mask(root, frame.frame_id, label_map_to_onehot(labels, ds.n_objects))
    return read_scene(root)
