"""Density activation: the truncated exponential of Instant-NGP / K-Planes."""

from __future__ import annotations

import torch


class _TruncExp(torch.autograd.Function):
    """exp(x) whose gradient uses a clamped exponent, so large raw densities cannot produce inf gradients."""

    @staticmethod
    def forward(ctx, x: torch.Tensor, clamp: float) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(x)
        ctx.clamp = clamp
        return torch.exp(x.clamp(max=clamp))

    @staticmethod
    def backward(ctx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:  # type: ignore[override]
        (x,) = ctx.saved_tensors
        return grad * torch.exp(x.clamp(-ctx.clamp, ctx.clamp)), None


def trunc_exp(x: torch.Tensor, clamp: float = 15.0) -> torch.Tensor:
    """exp(min(x, clamp)) in the forward pass; gradient exp(clamp(x)) (never inf, never 0 above the clamp)."""
    return _TruncExp.apply(x.float(), float(clamp))
