"""Volume rendering with log-space transmittance.

With optical thickness ``tau_i = sigma_i * delta_i`` and ``T_i`` the cumulative
sum of ``tau`` before sample ``i``, the weight of sample ``i`` is
``exp(-T_i) - exp(-T_{i+1}) = exp(-T_i) * (-expm1(-tau_i))``. Summing in log
space (no running product of ``1 - alpha``) keeps the weights finite and in
[0, 1] for densities from 0 to the float32 limit, and they sum exactly to
``1 - exp(-T_last)``, the accumulation.
"""

from __future__ import annotations

import torch

MAX_THICKNESS = 1e10
"""Optical thickness cap of one sample: beyond it the sample is opaque anyway, and inf * 0 cannot occur."""


def render_weights(density: torch.Tensor, deltas: torch.Tensor) -> torch.Tensor:
    """``density`` [R, S] and ``deltas`` [R, S] -> weights [R, S] (float32)."""
    tau = torch.nan_to_num(density.float() * deltas.float(), nan=0.0, posinf=MAX_THICKNESS).clamp(0.0, MAX_THICKNESS)
    # exclusive cumulative sum: the transmittance exponent before each sample (no large - large cancellation)
    before = torch.cat([torch.zeros_like(tau[:, :1]), torch.cumsum(tau[:, :-1], dim=-1)], dim=-1)
    return torch.exp(-before) * (-torch.expm1(-tau))


def render_rgb(weights: torch.Tensor, rgb: torch.Tensor, background: torch.Tensor) -> torch.Tensor:
    """[R, S] x [R, S, 3] -> [R, 3]; what the samples do not cover shows ``background`` [3]."""
    acc = weights.sum(dim=-1, keepdim=True)
    return (weights[..., None] * rgb.float()).sum(dim=-2) + (1.0 - acc) * background.to(rgb.device)


def render_accumulation(weights: torch.Tensor) -> torch.Tensor:
    return weights.sum(dim=-1)


def render_depth(weights: torch.Tensor, mids: torch.Tensor, nears: torch.Tensor, fars: torch.Tensor) -> torch.Tensor:
    """Expected distance of the visible surface [R], clamped to the ray's [near, far]."""
    acc = weights.sum(dim=-1)
    depth = (weights * mids).sum(dim=-1) / acc.clamp(min=1e-10)
    return torch.maximum(torch.minimum(depth, fars), nears)


def render_features(weights: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
    """Weighted sum of per-sample features [R, S, C] -> [R, C] (logits, embeddings)."""
    return (weights[..., None] * features.float()).sum(dim=-2)
