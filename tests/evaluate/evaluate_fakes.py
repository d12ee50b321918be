"""A tiny scene whose images are the renders of a fake truth renderer, a fake run and a fake text encoder.

Everything has a known answer: the fake run returns the truth plus +-0.1 on
the fridge's pixels only, so every PSNR below is computable by hand.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from stages.scene import Camera, Frame, SceneDataset, label_map_to_onehot, write_mask, write_scene

W, H = 16, 12
OBJECTS = ["fridge", "drawer"]
FRIDGE_COLS = slice(0, 6)
DRAWER_COLS = slice(10, 16)
ERROR = 0.1


def ids_map() -> np.ndarray:
    ids = np.zeros((H, W), dtype=np.int32)
    ids[:, FRIDGE_COLS] = 1
    ids[:, DRAWER_COLS] = 2
    return ids


class FakeTruthRenderer:
    """Flat colours: each object's grey level encodes its state; background mid grey."""

    def __init__(self) -> None:
        self.calls = 0

    def render(self, c2w, states, camera=None):
        self.calls += 1
        if not isinstance(states, dict):
            states = dict(zip(OBJECTS, states, strict=True))
        rgb = np.full((H, W, 3), 0.5, dtype=np.float32)
        rgb[:, FRIDGE_COLS] = 0.2 + 0.5 * states.get("fridge", 0.0)
        rgb[:, DRAWER_COLS] = 0.25 + 0.5 * states.get("drawer", 0.0)
        return {"rgb": rgb, "depth": np.ones((H, W), np.float32), "ids": ids_map()}


def _checker() -> np.ndarray:
    """+-ERROR on the fridge's pixels (sign alternating), 0 elsewhere: MSE there is exactly ERROR**2."""
    sign = np.where((np.add.outer(np.arange(H), np.arange(W)) % 2) == 0, 1.0, -1.0)
    out = np.zeros((H, W, 3))
    out[:, FRIDGE_COLS] = ERROR * sign[:, FRIDGE_COLS, None]
    return out


def _accumulation() -> np.ndarray:
    """The fridge 0.3 opaque, the drawer 0.5, the rest of the room 0.9: object mean 0.4 (equal pixel counts)."""
    acc = np.full((H, W), 0.9)
    acc[:, FRIDGE_COLS], acc[:, DRAWER_COLS] = 0.3, 0.5
    return acc


class FakeRun:
    """The model API: ``objects`` and ``render(camera, c2w, states, frame_index)``."""

    def __init__(self, dataset: SceneDataset, truth: FakeTruthRenderer) -> None:
        self.objects = list(dataset.objects)
        self.ds = dataset
        self.truth = truth
        self.rendered: list[tuple[int | None, dict | None]] = []

    def render(self, camera, c2w, states, frame_index=None, outputs=None):
        self.rendered.append((frame_index, states))
        frame = self.ds.frames[frame_index]
        if states == frame.state:  # the held-out view at its own state: the stored (PNG) image
            base = self.ds.load_image(frame).astype(np.float64)
        else:
            base = self.truth.render(c2w, states)["rgb"].astype(np.float64)
        probs = label_map_to_onehot(np.array([[-1, 0, 1][i] for i in ids_map().ravel()]).reshape(H, W), 2)
        return {"rgb": base + _checker(), "depth": np.ones((H, W)), "accumulation": _accumulation(),
                "probs": probs.astype(np.float32)}


def make_eval_dataset(root: Path, n_frames: int = 8) -> SceneDataset:
    """Frames on the state diagonal (fridge = drawer), images = fake truth renders saved as PNG."""
    truth = FakeTruthRenderer()
    camera = Camera(fx=20.0, fy=20.0, cx=W / 2, cy=H / 2, width=W, height=H)
    (root / "images").mkdir(parents=True, exist_ok=True)
    frames = []
    labels = np.array([[-1, 0, 1][i] for i in ids_map().ravel()]).reshape(H, W)
    for i in range(n_frames):
        t = i / (n_frames - 1)
        state = {"fridge": t, "drawer": t}
        c2w = np.eye(4)
        c2w[:3, 3] = [0.1 * i, 0.0, 3.0]
        rgb = truth.render(c2w, state)["rgb"]
        path = f"images/frame_{i:05d}.png"
        cv2.imwrite(str(root / path), np.round(rgb[..., ::-1] * 255).astype(np.uint8))
        write_mask(root, f"{i:05d}", label_map_to_onehot(labels, 2))
        frames.append(Frame(file_path=path, c2w=c2w, state=state, split="test" if i % 2 == 0 else "train",
                            source_index=i))
    ds = SceneDataset(root=root, camera=camera, frames=frames, objects=OBJECTS, object_ids=[1, 2],
                      prompts={"fridge": {"synonyms": ["refrigerator"]}, "drawer": {"synonyms": ["kitchen drawer"]}},
                      meta={"units": "m"})
    write_scene(ds, root)
    return ds


class SlidingTruthRenderer(FakeTruthRenderer):
    """A truth whose ids follow the state, in colour: the fridge is 3 columns wide and slides right with its state
    (columns ``[round(3 s), round(3 s) + 3)``: 0..2 shut, 3..5 open), so where it was and where it is differ; the
    drawer stays on columns 10..15. Red, green and blue differ on every surface. With ``shadow_column`` the fridge,
    once at least half open, casts a shadow there (``shadow_ids`` ``[1, H, W]``, as the capture renderer reports)."""

    def __init__(self, shadow_column: int | None = None) -> None:
        super().__init__()
        self.shadow_column = shadow_column

    @staticmethod
    def fridge_cols(state: float) -> slice:
        start = round(float(3 * state))
        return slice(start, start + 3)

    def render(self, c2w, states, camera=None):
        self.calls += 1
        if not isinstance(states, dict):
            states = dict(zip(OBJECTS, states, strict=True))
        fridge, drawer = states.get("fridge", 0.0), states.get("drawer", 0.0)
        ids = np.zeros((H, W), dtype=np.int32)
        ids[:, self.fridge_cols(fridge)] = 1
        ids[:, DRAWER_COLS] = 2
        rgb = np.empty((H, W, 3), dtype=np.float32)
        rgb[:] = (0.5, 0.4, 0.3)
        rgb[ids == 1] = (0.2 + 0.5 * fridge, 0.3, 0.1)
        rgb[ids == 2] = (0.1, 0.25 + 0.5 * drawer, 0.6)
        out = {"rgb": rgb, "depth": np.ones((H, W), np.float32), "ids": ids}
        if self.shadow_column is not None:
            shadow = np.zeros((1, H, W), dtype=np.int32)
            if fridge >= 0.5:
                shadow[0, :, self.shadow_column] = 1
            out["shadow_ids"] = shadow
        return out


class TruthRun(FakeRun):
    """The fake run, rendering the truth renderer's image at every state (also a view's own state, where FakeRun
    returns the stored PNG) plus the same +-ERROR on columns 0..5: every PSNR is exact, none has PNG rounding."""

    def render(self, camera, c2w, states, frame_index=None, outputs=None):
        self.rendered.append((frame_index, states))
        base = self.truth.render(c2w, states)["rgb"].astype(np.float64)
        probs = label_map_to_onehot(np.array([[-1, 0, 1][i] for i in ids_map().ravel()]).reshape(H, W), 2)
        return {"rgb": base + _checker(), "depth": np.ones((H, W)), "accumulation": _accumulation(),
                "probs": probs.astype(np.float32)}
