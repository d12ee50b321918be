"""The interaction-aware language table (docs/method.md section 7).

Instead of a dense 3D language field, one learnable embedding per (object,
state bucket) plus one for the background. A sample retrieves the entry of its
region ``u`` (argmax over all alpha + 1 logits, so background samples get the
background entry) interpolated linearly between buckets by ``kappa_u`` (paper)
or by the normalised frame index (reference code). Entries are unit-normalised
and volume-rendered at the final level only.

Rendering never looks entries up per sample. Within one ray every sample of
region ``u`` has the same state, hence the same entry ``e_u``, so the rendered
feature is ``sum_u W_u e_u / |e_u|`` with ``W_u`` the summed weights of the
ray's samples in region ``u``: a scatter of scalars per sample, then one
``[R, K] @ [K, D]`` product with the K = alpha x buckets + 1 table rows.
``|e_u|`` of an interpolated entry comes from the table's Gram matrix. The
per-sample ``forward`` is the same function written point by point (tests
hold the two equal, values and gradients); it is what a 3D query of single
points would use.
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

    def _buckets(self, value: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """State value(s) in [0, 1] -> (lower bucket, upper bucket, fraction towards the upper)."""
        pos = value.detach().float().clamp(0, 1) * (self.buckets - 1)
        lo = pos.floor().long().clamp(0, max(self.buckets - 2, 0))
        hi = (lo + 1).clamp(max=self.buckets - 1)
        return lo, hi, pos - lo.float()

    def render(self, region_weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        """Volume-rendered embedding of rays, from per-region weights.

        ``region_weights`` [R, alpha + 1]: summed (detached) sample weights of each
        region along each ray, background last; ``values`` [R, alpha + 1]: the
        interpolation value of each region (its object's state, or the frame
        time; the background column is ignored) -> [R, D].
        """
        with torch.autocast(region_weights.device.type, enabled=False):  # a Gram matrix in bf16 loses the norms
            return self._render(region_weights, values)

    def _render(self, region_weights: torch.Tensor, values: torch.Tensor) -> torch.Tensor:
        a, b, d = self.n_objects, self.buckets, self.dim
        rows = torch.cat([self.table.reshape(a * b, d), self.background[None]], dim=0)  # [K, D]
        gram = rows @ rows.T
        k = rows.shape[0]
        weights = region_weights.float()
        coef_bg = weights[:, a:] / gram[k - 1, k - 1].clamp_min(1e-24).sqrt()
        if a == 0:
            return coef_bg @ rows
        lo, hi, frac = self._buckets(values[:, :a])
        first = torch.arange(a, device=lo.device) * b
        ilo, ihi = lo + first, hi + first  # [R, alpha] rows of the interpolated pair
        # |(1 - f) e_lo + f e_hi|^2 from the Gram matrix; the clamp is F.normalize's eps of 1e-12 on the norm
        sq = ((1 - frac) ** 2 * gram[ilo, ilo] + 2 * frac * (1 - frac) * gram[ilo, ihi] + frac**2 * gram[ihi, ihi])
        scale = weights[:, :a] / sq.clamp_min(1e-24).sqrt()
        coef = torch.zeros(weights.shape[0], k - 1, device=weights.device, dtype=weights.dtype)
        coef = coef.scatter_add(1, ilo, scale * (1 - frac)).scatter_add(1, ihi, scale * frac)
        return torch.cat([coef, coef_bg], dim=1) @ rows

    def forward(self, region: torch.Tensor, value: torch.Tensor) -> torch.Tensor:
        """``region`` [N] long in 0..alpha (alpha = background), ``value`` [N] in [0, 1] -> [N, D] unit rows."""
        lo, hi, frac = self._buckets(value)
        frac = frac.unsqueeze(-1)
        obj = region.clamp(max=max(self.n_objects - 1, 0))
        if self.n_objects > 0:
            emb = self.table[obj, lo] * (1 - frac) + self.table[obj, hi] * frac
            is_bg = (region >= self.n_objects).unsqueeze(-1)
            emb = torch.where(is_bg, self.background.expand_as(emb), emb)
        else:
            emb = self.background.expand(region.shape[0], -1)
        return F.normalize(emb, dim=-1)
