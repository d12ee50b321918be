"""Camera refinement: a pose correction per training frame, learned with the field (``train.camera_opt``), and the
alignment of a held-out view's pose to a refined run's world before it is scored (docs/model.md, "Camera refinement").

A correction is a 6-vector ``[t, w]`` in the normalised scene: ``t`` moves the camera centre (scene units), ``w`` is
an axis-angle rotation (radians) of the camera about its centre, in world axes. A ray of the frame becomes
``o + t``, ``exp(w) d`` (the SO3xR3 form of nerfacto's camera optimiser), and its near and far distances are those
of the corrected ray. Everything is tensor arithmetic on the device: no value is read back to the host.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from .rays import RayBundle
from .scene_normalization import SceneNormalization, aabb_near_far

CAMERA_OPT_MODES = ("off", "SO3xR3")
ALIGN_STEPS = 100
"""Adam steps of a held-out view's alignment (the evaluation's test-time optimisation, model frozen)."""
ALIGN_RAYS = 1024
"""Pixels of the view the alignment fits, drawn once by a generator seeded per view: the same pixels on every run."""
ALIGN_LR = 1e-3
"""Peak learning rate of the alignment, decayed by a cosine to a tenth over ``ALIGN_STEPS``."""


def so3_exp(w: torch.Tensor) -> torch.Tensor:
    """Rotation matrices ``[N, 3, 3]`` of axis-angle vectors ``[N, 3]`` (Rodrigues' formula; a Taylor series near 0,
    chosen by ``torch.where`` so that no branch is decided on the host and the gradient at 0 is finite)."""
    theta2 = (w * w).sum(-1)
    small = theta2 < 1e-6
    theta = theta2.clamp(min=1e-6).sqrt()
    a = torch.where(small, 1.0 - theta2 / 6.0, torch.sin(theta) / theta)
    b = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(theta)) / theta.square())
    zero = torch.zeros_like(w[:, 0])
    k = torch.stack([zero, -w[:, 2], w[:, 1], w[:, 2], zero, -w[:, 0], -w[:, 1], w[:, 0], zero], -1).view(-1, 3, 3)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand_as(k)
    return eye + a[:, None, None] * k + b[:, None, None] * (k @ k)


def correct_rays(rays: RayBundle, adjustment: torch.Tensor, near_plane: float) -> RayBundle:
    """``rays`` moved by their own ``[R, 6]`` corrections ``[t, w]``, with the corrected rays' near and far."""
    origins = rays.origins + adjustment[:, :3]
    directions = torch.einsum("rij,rj->ri", so3_exp(adjustment[:, 3:]), rays.directions)
    nears, fars = aabb_near_far(origins, directions, near_plane)
    return RayBundle(origins, directions, nears, fars, rays.states, rays.times)


def safe_norm(x: torch.Tensor) -> torch.Tensor:
    """Row lengths with a finite gradient at 0."""
    return (x.square().sum(-1) + 1e-12).sqrt()


class CameraCorrections(torch.nn.Module):
    """One correction per training frame; ``rows`` maps a dataset frame index to its row (-1: not a training frame,
    never looked up during training)."""

    def __init__(self, frame_rows: torch.Tensor, n_rows: int) -> None:
        super().__init__()
        self.adjustment = torch.nn.Parameter(torch.zeros(n_rows, 6))
        self.register_buffer("rows", frame_rows.long(), persistent=False)

    def correct(self, rays: RayBundle, frames: torch.Tensor, near_plane: float) -> RayBundle:
        return correct_rays(rays, self.adjustment[self.rows[frames]], near_plane)

    def penalty(self, translation: float, rotation: float) -> torch.Tensor:
        """The mean translation length and rotation angle, weighted (keeps the corrections small)."""
        a = self.adjustment
        return translation * safe_norm(a[:, :3]).mean() + rotation * safe_norm(a[:, 3:]).mean()


def exponential_factor(step: int, total: int, final_ratio: float, time_fraction: float = 0.0) -> float:
    """The corrections' learning rate relative to its peak: ``final_ratio ** progress`` (progress as in
    ``trainer.lr_factor``: the larger of the step fraction and the time budget's share)."""
    progress = min(max(step / max(total, 1), time_fraction), 1.0)
    return final_ratio**progress


def corrected_c2w(c2w: np.ndarray, adjustment: np.ndarray, norm: SceneNormalization) -> np.ndarray:
    """The dataset-world camera-to-world of ``c2w`` moved by a normalised-scene correction ``[t, w]``."""
    adjustment = np.asarray(adjustment, dtype=np.float64)
    rot = so3_exp(torch.tensor(adjustment[None, 3:], dtype=torch.float64))[0].numpy()
    out = np.asarray(c2w, dtype=np.float64).copy()
    out[:3, :3] = rot @ out[:3, :3]
    # the normalisation is x_unit = A x_world + b: a step t in the unit box is A^-1 t in the world
    out[:3, 3] = out[:3, 3] + np.linalg.solve(norm.transform[:3, :3], adjustment[:3])
    return out


def correction_size(adjustment: np.ndarray, norm: SceneNormalization) -> dict[str, float]:
    """A correction's rotation (degrees) and translation (dataset units)."""
    adjustment = np.asarray(adjustment, dtype=np.float64)
    return {
        "rotation_deg": float(np.degrees(np.linalg.norm(adjustment[3:]))),
        "translation": float(np.linalg.norm(adjustment[:3]) / norm.scale),
    }


def align_rays(
    render: callable,
    origins: torch.Tensor,
    directions: torch.Tensor,
    target: torch.Tensor,
    near_plane: float,
    seed: int,
    steps: int = ALIGN_STEPS,
    rays_per_step: int = ALIGN_RAYS,
    lr: float = ALIGN_LR,
) -> np.ndarray:
    """The ``[6]`` correction of one view that makes ``render`` (a frozen model: RayBundle -> rgb ``[R, 3]``) best
    match ``target`` ``[N, 3]`` at the view's rays ``[N, 3]`` (normalised scene).

    ``steps`` Adam steps on one fixed set of ``rays_per_step`` pixels, drawn by a generator seeded with ``seed``:
    a fixed objective, which Adam descends, where new pixels at every step would make it a random walk of a
    learning rate per step (on the demo, views at their true poses were moved by 0.65 degrees and lost 2.4 dB). The
    correction returned is the one of least error on those pixels among every step's, zero included: the alignment
    never leaves a view worse on them than its given pose.
    """
    adjustment = torch.zeros(1, 6, dtype=torch.float32, device=origins.device, requires_grad=True)
    optimizer = torch.optim.Adam([adjustment], lr=lr, eps=1e-15)
    n = origins.shape[0]
    pick = torch.randperm(n, generator=torch.Generator().manual_seed(seed))[: min(rays_per_step, n)]
    pick = pick.to(origins.device)
    o, d, rgb = origins[pick], directions[pick], target[pick]
    best, best_loss = adjustment.detach().clone(), math.inf
    for i in range(steps + 1):
        for group in optimizer.param_groups:
            group["lr"] = lr * (0.1 + 0.9 * 0.5 * (1.0 + math.cos(math.pi * i / max(steps, 1))))
        rays = correct_rays(RayBundle(o, d, o[:, 0], o[:, 0]), adjustment.expand(len(pick), 6), near_plane)
        loss = (render(rays) - rgb).square().mean()
        value = float(loss.detach())  # the evaluation may wait for the device: one read per step
        if value < best_loss:
            best, best_loss = adjustment.detach().clone(), value
        if i == steps:  # the last pose's error is measured, not stepped from
            break
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        optimizer.step()
    return best[0].cpu().double().numpy()
