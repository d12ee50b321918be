"""The CoNeRF-style radiance field: a coordinate network conditioned on mask-gated attributes.

CoNeRF (Kania et al., CVPR 2022) feeds a NeRF MLP the position and the
attribute vector after each attribute is multiplied by the point's mask
probability for that attribute, so a point only "sees" the attributes of the
object it belongs to (background points see none). The original runs on
HyperNeRF (positional-encoding MLPs, hours per scene on a GPU). To train in
the same CPU budget as the other methods this field swaps the positional
encoding of space for a multi-scale K-Planes tri-plane (xy, xz, yz only; no
plane touches an attribute) and keeps a NeRF-style sinusoidal encoding of the
gated attributes; both are concatenated and decoded by a small ReLU MLP
(density + geometry features), then a colour MLP on spherical harmonics of the
view direction, as in the shared radiance field. State changes therefore have
to be expressed by the MLP, not by planes: that is the CoNeRF design.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ..config import ConerfConfig, RadianceFieldConfig
from ..encodings import MultiScaleKPlanes, PlaneGrids, SHEncoding
from ..mlp import mlp
from .activations import trunc_exp


def attribute_encoding(values: torch.Tensor, frequencies: int) -> torch.Tensor:
    """[N, A] in [-1, 1] -> [N, A (1 + 2 F)]: the value, then sin/cos of 2^l pi v for l < F."""
    if frequencies <= 0 or values.shape[-1] == 0:
        return values
    scales = (2.0 ** torch.arange(frequencies, device=values.device, dtype=values.dtype)) * math.pi
    arg = values.unsqueeze(-1) * scales  # [N, A, F]
    return torch.cat([values, torch.sin(arg).flatten(1), torch.cos(arg).flatten(1)], dim=-1)


class ConerfField(nn.Module):
    """Coordinates [N, 3 + alpha] = (x, y, z, gated attributes) -> density [N], rgb [N, 3]."""

    def __init__(self, config: RadianceFieldConfig, conerf: ConerfConfig, n_objects: int) -> None:
        super().__init__()
        self.config, self.conerf, self.n_objects = config, conerf, n_objects
        r = config.base_resolution
        self.encoding = MultiScaleKPlanes([r, r, r], config.channels, config.scales, None, 3, config.init_range)
        attr_dim = n_objects * (1 + 2 * max(conerf.attribute_frequencies, 0))
        self.density_mlp = mlp(self.encoding.out_dim + attr_dim, conerf.hidden, conerf.hidden_layers,
                               1 + config.geo_feat_dim)
        self.direction_encoding = SHEncoding(config.sh_degree)
        self.color_mlp = mlp(self.direction_encoding.out_dim + config.geo_feat_dim, config.color_hidden,
                             config.color_layers, 3)

    def density(self, coords: torch.Tensor, cache: PlaneGrids | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """-> density [N] (float32), geometry features [N, geo_feat_dim]."""
        spatial = self.encoding(coords[:, :3], cache)
        attrs = attribute_encoding(coords[:, 3:].to(spatial.dtype), self.conerf.attribute_frequencies)
        h = self.density_mlp(torch.cat([spatial, attrs], dim=-1))
        raw, geo = h.split([1, h.shape[1] - 1], dim=1)  # one gradient for h (two slices' would each zero-fill one)
        raw = raw.squeeze(1)
        return trunc_exp(raw + self.config.density_bias, self.config.density_exp_clamp), geo

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
