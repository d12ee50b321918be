"""The interaction-aware language table (METHOD.md section 7).

Instead of a dense 3D language field, one learnable embedding per (object,
state bucket) plus one for the background. A sample retrieves the entry of its
region ``u`` (argmax over all alpha + 1 logits, so background samples get the
background entry) interpolated linearly between buckets by ``kappa_u`` (paper)
or by the normalised frame index (reference code). Entries are unit-normalised
and volume-rendered at the final level only.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class LanguageTable(nn.Module):
    """[alpha, buckets, D] object entries + [D] background entry."""

    def __init__(self, n_objects: int, buckets: int, dim: int, init: torch.Tensor | None = None,
                 background: torch.Tensor | None = None) -> None:
        super().__init__()
        if buckets < 1:
            raise ValueError(f"the language table needs at least one state bucket, got {buckets}")
        self.n_objects, self.buckets, self.dim = n_objects, buckets, dim
        table = torch.randn(n_objects, buckets, dim) * 0.1 if init is None else init.clone().float()
        bg = torch.randn(dim) * 0.1 if background is None else background.clone().float()
        self.table = nn.Parameter(table)
        self.background = nn.Parameter(bg)

    def forward(self, region: torch.Tensor, value: torch.Tensor) -> torch.Tensor:
        """``region`` [N] long in 0..alpha (alpha = background), ``value`` [N] in [0, 1] -> [N, D] unit rows."""
        pos = value.detach().float().clamp(0, 1) * (self.buckets - 1)
        lo = pos.floor().long().clamp(0, max(self.buckets - 2, 0))
        hi = (lo + 1).clamp(max=self.buckets - 1)
        frac = (pos - lo.float()).unsqueeze(-1)
        obj = region.clamp(max=max(self.n_objects - 1, 0))
        if self.n_objects > 0:
            emb = self.table[obj, lo] * (1 - frac) + self.table[obj, hi] * frac
            is_bg = (region >= self.n_objects).unsqueeze(-1)
            emb = torch.where(is_bg, self.background.expand_as(emb), emb)
        else:
            emb = self.background.expand(region.shape[0], -1)
        return F.normalize(emb, dim=-1)
