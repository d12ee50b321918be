"""The main radiance field: multi-scale K-Planes over (x, y, z, k) -> density and view-dependent colour."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from ..config import RadianceFieldConfig
from ..encodings import MultiScaleKPlanes, PlaneGrids, SHEncoding
from ..mlp import mlp
from .activations import trunc_exp


class RadianceField(nn.Module):
    """K-Planes field over an N-D coordinate whose first 3 axes are space.

    LiveScene calls it with 4D coordinates (x, y, z, k) and the six planes of
    all pairs; baselines pass other ``pairs`` and wider coordinates. Features of
    all scales are concatenated (3 x 32 = 96), decoded by a density MLP
    (96 -> 64 -> 1 + 15) and a colour MLP (16 SH + 15 -> 64 -> 64 -> 3).
    """

    def __init__(self, config: RadianceFieldConfig, n_dims: int = 4,
                 pairs: Sequence[tuple[int, int]] | None = None) -> None:
        super().__init__()
        self.config = config
        base = [config.base_resolution] * 3 + [config.k_resolution] * (n_dims - 3)
        self.encoding = MultiScaleKPlanes(base, config.channels, config.scales, pairs, 3, config.init_range)
        self.density_mlp = mlp(self.encoding.out_dim, config.hidden, 1, 1 + config.geo_feat_dim)
        self.direction_encoding = SHEncoding(config.sh_degree)
        self.color_mlp = mlp(self.direction_encoding.out_dim + config.geo_feat_dim, config.color_hidden,
                             config.color_layers, 3)

    def density(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``coords`` [N, D] in [-1, 1] -> density [N] (float32), geometry features [N, geo_feat_dim]."""
        h = self.density_mlp(self.encoding(coords, cache))
        raw, geo = h.split([1, h.shape[1] - 1], dim=1)  # one gradient for h (two slices' would each zero-fill one)
        raw = raw.squeeze(1)
        sigma = trunc_exp(raw + self.config.density_bias, self.config.density_exp_clamp)
        return sigma, geo

    def color(self, geo: torch.Tensor, encoded_directions: torch.Tensor) -> torch.Tensor:
        """Geometry features [N, geo_feat_dim] and ``direction_encoding`` of the view directions [N, sh] -> rgb
        [N, 3] in (0, 1). The encoding is the caller's: it depends on the ray only, so it is computed per ray."""
        d = encoded_directions.to(geo.dtype)
        return torch.sigmoid(self.color_mlp(torch.cat([d, geo], dim=-1)).float())

    def forward(self, coords: torch.Tensor, directions: torch.Tensor,
                cache: PlaneGrids | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """-> density [N], rgb [N, 3] in (0, 1)."""
        sigma, geo = self.density(coords, cache)
        return sigma, self.color(geo, self.direction_encoding(directions))
