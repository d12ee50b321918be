"""Learned object states (docs/method.md section 6): a 1D grid over normalised frame index -> kappa per object.

257 x 4 grid vertices plus a small sinusoidal encoding of the frame index,
decoded by an MLP (4 -> 32 -> alpha) with a sigmoid so states stay in [0, 1].
Only key frames are supervised (MSE); the RGB loss reaches the grid through
the k coordinate of every sample.
"""

from __future__ import annotations

import torch
from torch import nn

from ..config import StateConfig
from ..encodings import Grid1DEncoding, sinusoidal_encoding
from ..mlp import mlp


class StateField(nn.Module):
    """Normalised frame index t [N] in [0, 1] -> states [N, alpha] in (0, 1)."""

    def __init__(self, config: StateConfig, n_objects: int) -> None:
        super().__init__()
        self.config = config
        self.grid = Grid1DEncoding(config.grid_resolution, config.grid_channels, config.grid_init)
        self.decoder = mlp(config.grid_channels, config.hidden, 1, max(n_objects, 1))
        self.n_objects = n_objects

    def forward(self, t: torch.Tensor) -> torch.Tensor:
        h = self.grid(t.float())
        if self.config.positional_encoding:
            h = h + sinusoidal_encoding(t, self.config.grid_channels)
        return torch.sigmoid(self.decoder(h))[:, : self.n_objects]
