"""Proposal density fields: small single-scale K-Planes over (x, y, z, k) with a one-hidden-layer MLP."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ..encodings import KPlanesEncoding, PlaneGrids
from ..mlp import mlp
from .activations import trunc_exp


class DensityField(nn.Module):
    """Density only (no colour): what a proposal level needs to place the next level's samples."""

    def __init__(self, resolution: Sequence[int], channels: int, hidden: int, init_range: Sequence[float],
                 pairs: Sequence[tuple[int, int]] | None = None, density_bias: float = -1.0,
                 exp_clamp: float = 15.0) -> None:
        super().__init__()
        self.encoding = KPlanesEncoding(resolution, channels, pairs, 3, init_range)
        self.mlp = mlp(channels, hidden, 1, 1)
        self.density_bias = density_bias
        self.exp_clamp = exp_clamp

    def forward(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        """``coords`` [N, D] in [-1, 1] -> density [N] (float32)."""
        raw = self.mlp(self.encoding(coords, cache)).squeeze(1)  # a view: [:, 0]'s backward zero-fills a copy
        return trunc_exp(raw + self.density_bias, self.exp_clamp)
