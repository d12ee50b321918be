"""Training rays: every pixel of the training images with its colour, state vector, time and mask label.

Images are kept as uint8 and label maps as int8 (a few bytes per pixel);
rays are built per batch from per-camera pixel directions and the frame's
pose. Batches are drawn uniformly over all training pixels by a dedicated
``torch.Generator`` whose state the trainer checkpoints, so a resumed run
draws exactly the rays an uninterrupted run would.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from stages.scene import Frame, SceneDataset, SceneError
from stages.scene.camera import pixel_directions
from stages.scene.key_frame_states import frame_times
from stages.scene.masks import unreliable_masks

from .rays import RayBundle
from .scene_normalization import SceneNormalization, aabb_near_far


@dataclass
class RayBatch:
    """Rays plus their supervision."""

    rays: RayBundle
    rgb: torch.Tensor
    """[R, 3] target colour in [0, 1]."""
    labels: torch.Tensor
    """[R] long: object index 0..alpha-1, alpha = background, -1 = no reliable mask."""
    frames: torch.Tensor
    """[R] long: index of the frame in the dataset's frame list."""


def state_vector(ds: SceneDataset, frame: Frame) -> np.ndarray:
    """The frame's state per object in dataset order; NaN where the frame does not give one."""
    out = np.full(ds.n_objects, np.nan, dtype=np.float32)
    for j, name in enumerate(ds.objects):
        if frame.state and name in frame.state:
            out[j] = frame.state[name]
    return out


def label_maps(ds: SceneDataset, frames: list[Frame]) -> np.ndarray:
    """int8 label maps [F, H, W] of ``frames``: object index, alpha = background, -1 = no label; a frame without
    a mask, or with an object's mask too small to trust (``unreliable_masks`` over the dataset's frames), is all -1.
    """
    cam = ds.camera_of(frames[0])
    out = np.full((len(frames), cam.height, cam.width), -1, dtype=np.int8)
    if not ds.has_masks or ds.n_objects == 0:
        return out
    # one read of every mask: the objects' usual sizes come from every frame (as the labels stage counts them),
    # the label maps from the requested ones
    rows: dict[str, list[int]] = {}  # by frame id: the caller's Frame objects need not be the dataset's
    for k, f in enumerate(frames):
        rows.setdefault(f.frame_id, []).append(k)
    ids, counts = [], []
    for f in ds.frames:
        mask = ds.load_mask_or_none(f)
        if mask is None:
            continue
        ids.append(f.frame_id)
        counts.append(mask[..., :-1].reshape(-1, ds.n_objects).sum(0))
        if f.frame_id in rows:
            labels = np.argmax(mask, axis=-1).astype(np.int8)
            labels[~mask.any(axis=-1)] = -1
            out[rows[f.frame_id]] = labels
    if ids:
        unreliable = {i for i, small in zip(ids, unreliable_masks(np.array(counts), cam.height, cam.width),
                                            strict=True) if small.any()}
        out[[k for k, f in enumerate(frames) if f.frame_id in unreliable]] = -1
    return out


def _nominal(rgb: np.ndarray, log_gain: list[float] | None) -> np.ndarray:
    """The image at the capture's nominal exposure: its measured gain divided out (no-op without one)."""
    return rgb if log_gain is None else rgb * np.exp(-np.asarray(log_gain, np.float32))


class RayDataset:
    """The rays of a list of frames (one shared image size), on the CPU or the training device."""

    def __init__(self, ds: SceneDataset, frames: list[Frame], norm: SceneNormalization, near_plane: float,
                 device: torch.device | str = "cpu", need_states: bool = True,
                 log_gains: dict[str, list[float]] | None = None) -> None:
        """``log_gains``: a measured per-channel log gain per frame id, divided out of that frame's colours
        (``model.appearance.mode: measured``); frames it does not name keep theirs."""
        if not frames:
            raise SceneError(ds.root / "transforms.json", "no frames to train on", "give the dataset train frames")
        self.ds, self.frames, self.norm, self.near_plane = ds, frames, norm, near_plane
        self.need_states = need_states
        self.device = torch.device(device)
        cams = {(ds.camera_of(f).width, ds.camera_of(f).height) for f in frames}
        if len(cams) > 1:
            raise SceneError(ds.root / "transforms.json", f"frames have several image sizes {sorted(cams)}",
                             "resize all images to one size (the model samples rays over a uniform image grid)")
        self.width, self.height = next(iter(cams))
        index_of = {id(f): i for i, f in enumerate(ds.frames)}
        self.frame_index = torch.tensor([index_of[id(f)] for f in frames], dtype=torch.long)
        times = frame_times(ds.frames)
        self.times = torch.tensor(times[self.frame_index.numpy()], dtype=torch.float32)
        states = np.stack([state_vector(ds, f) for f in frames]) if ds.n_objects else np.zeros((len(frames), 0))
        if need_states and np.isnan(states).any():
            bad = [frames[i].file_path for i in np.where(np.isnan(states).any(axis=1))[0][:3]]
            raise SceneError(ds.root / "transforms.json", f"frames {bad} have no state for every object",
                             "run `livescene states` to interpolate states, or train with --state-mode learned")
        self.states = torch.tensor(np.nan_to_num(states, nan=0.0), dtype=torch.float32)
        gains = log_gains or {}
        self.images = torch.from_numpy(np.stack([
            np.clip(_nominal(ds.load_image(f), gains.get(f.frame_id)) * 255.0 + 0.5, 0, 255).astype(np.uint8)
            for f in frames]))
        self.labels = torch.from_numpy(label_maps(ds, frames))
        c2w = np.stack([norm.pose(f.c2w) for f in frames])
        self.rotations = torch.tensor(c2w[:, :3, :3], dtype=torch.float32)
        self.centres = torch.tensor(c2w[:, :3, 3], dtype=torch.float32)
        cam = ds.camera_of(frames[0])
        v, u = np.meshgrid(np.arange(self.height), np.arange(self.width), indexing="ij")
        # per-camera directions (distortion undone once); frames with their own intrinsics get theirs
        self.cam_dirs = self._camera_directions(frames, u, v) if any(f.camera for f in frames) else None
        self.shared_dirs = torch.tensor(pixel_directions(cam, u, v), dtype=torch.float32).reshape(-1, 3)
        for name in ("images", "labels", "states", "times", "rotations", "centres", "shared_dirs", "frame_index"):
            setattr(self, name, getattr(self, name).to(self.device))
        if self.cam_dirs is not None:
            self.cam_dirs = self.cam_dirs.to(self.device)

    def _camera_directions(self, frames: list[Frame], u: np.ndarray, v: np.ndarray) -> torch.Tensor:
        dirs = [pixel_directions(self.ds.camera_of(f), u, v).reshape(-1, 3) for f in frames]
        return torch.tensor(np.stack(dirs), dtype=torch.float32)

    @property
    def n_rays(self) -> int:
        return len(self.frames) * self.height * self.width

    def batch(self, flat: torch.Tensor) -> RayBatch:
        """Rays of flat pixel indices (frame * H * W + row * W + col)."""
        if self.device.type == "cuda" and flat.device.type == "cpu":
            # indices drawn by the CPU generator (the same rays on any device): a copy from pageable memory would
            # wait for the GPU's queue once per step, one from pinned memory does not
            flat = flat.pin_memory().to(self.device, non_blocking=True)
        flat = flat.to(self.device)
        hw = self.height * self.width
        f, pix = flat // hw, flat % hw
        d_cam = self.cam_dirs[f, pix] if self.cam_dirs is not None else self.shared_dirs[pix]
        dirs = torch.einsum("rij,rj->ri", self.rotations[f], d_cam)
        dirs = dirs / dirs.norm(dim=-1, keepdim=True)
        origins = self.centres[f]
        nears, fars = aabb_near_far(origins, dirs, self.near_plane)
        row, col = pix // self.width, pix % self.width
        rgb = self.images[f, row, col].float() / 255.0
        states = self.states[f] if self.need_states else None  # learned-state mode: the model supplies them
        rays = RayBundle(origins, dirs, nears, fars, states, self.times[f])
        return RayBatch(rays, rgb, self.labels[f, row, col].long(), self.frame_index[f])

    def sample(self, n: int, generator: torch.Generator) -> RayBatch:
        """``n`` rays drawn uniformly over all pixels of all frames (with replacement)."""
        return self.batch(torch.randint(0, self.n_rays, (n,), generator=generator))
