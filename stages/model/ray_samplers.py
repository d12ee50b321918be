"""Ray samplers: uniform, PDF (inverse-CDF resampling) and the proposal schedule of Mip-NeRF 360.

Samples are kept as bin edges ``bins`` [R, S + 1] of distance along the ray
(normalised scene units); sample ``i`` covers ``[bins[i], bins[i + 1]]`` and
is evaluated at its midpoint. The k-projection of LiveScene happens in the
method (``methods/livescene.py``) at every level, between these samplers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .config import SamplingConfig


@dataclass
class RaySamples:
    """Bin edges along a batch of rays."""

    bins: torch.Tensor
    """[R, S + 1] distances, sorted along the last axis."""

    @property
    def starts(self) -> torch.Tensor:
        return self.bins[:, :-1]

    @property
    def ends(self) -> torch.Tensor:
        return self.bins[:, 1:]

    @property
    def mids(self) -> torch.Tensor:
        return 0.5 * (self.bins[:, 1:] + self.bins[:, :-1])

    @property
    def deltas(self) -> torch.Tensor:
        return self.bins[:, 1:] - self.bins[:, :-1]

    @property
    def n_samples(self) -> int:
        return self.bins.shape[1] - 1


def _jitter(shape: tuple[int, int], single: bool, generator: torch.Generator | None,
            device: torch.device) -> torch.Tensor:
    if single:
        return torch.rand(shape[0], 1, generator=generator, device=device).expand(shape)
    return torch.rand(shape, generator=generator, device=device)


def uniform_samples(nears: torch.Tensor, fars: torch.Tensor, n: int, jitter: bool = False, single_jitter: bool = False,
                    generator: torch.Generator | None = None) -> RaySamples:
    """``n`` equal bins between ``nears`` [R] and ``fars`` [R]; with ``jitter`` every edge moves inside its cell."""
    device = nears.device
    u = torch.linspace(0.0, 1.0, n + 1, device=device).expand(nears.shape[0], n + 1)
    if jitter:
        centres = 0.5 * (u[:, 1:] + u[:, :-1])
        upper = torch.cat([centres, u[:, -1:]], dim=-1)
        lower = torch.cat([u[:, :1], centres], dim=-1)
        u = lower + (upper - lower) * _jitter(tuple(u.shape), single_jitter, generator, device)
    bins = nears[:, None] + u * (fars - nears)[:, None]
    return RaySamples(bins)


def pdf_samples(samples: RaySamples, weights: torch.Tensor, n: int, jitter: bool = False, single_jitter: bool = False,
                padding: float = 0.01, generator: torch.Generator | None = None) -> RaySamples:
    """Resample ``n`` bins whose edges follow the piecewise-constant PDF of ``weights`` [R, S] over ``samples``."""
    weights = weights.detach().float() + padding
    eps = 1e-5
    wsum = weights.sum(dim=-1, keepdim=True)
    pad = torch.relu(eps - wsum)
    weights = weights + pad / weights.shape[-1]
    wsum = wsum + pad
    pdf = weights / wsum
    cdf = torch.clamp(torch.cumsum(pdf[:, :-1], dim=-1), max=1.0)
    cdf = torch.cat([torch.zeros_like(cdf[:, :1]), cdf, torch.ones_like(cdf[:, :1])], dim=-1)  # [R, S + 1]
    n_edges = n + 1
    device = weights.device
    if jitter:
        u = torch.linspace(0.0, 1.0 - 1.0 / n_edges, n_edges, device=device)
        u = u + _jitter((weights.shape[0], n_edges), single_jitter, generator, device) / n_edges
    else:
        u = torch.linspace(0.0, 1.0 - 1.0 / n_edges, n_edges, device=device) + 0.5 / n_edges
        u = u.expand(weights.shape[0], n_edges)
    u = u.contiguous()
    idx = torch.searchsorted(cdf, u, side="right")
    below = (idx - 1).clamp(0, cdf.shape[-1] - 1)
    above = idx.clamp(0, cdf.shape[-1] - 1)
    cdf0, cdf1 = torch.gather(cdf, 1, below), torch.gather(cdf, 1, above)
    b0, b1 = torch.gather(samples.bins, 1, below), torch.gather(samples.bins, 1, above)
    t = torch.clamp(torch.nan_to_num((u - cdf0) / (cdf1 - cdf0), nan=0.0), 0.0, 1.0)
    bins = b0 + t * (b1 - b0)
    bins, _ = torch.sort(bins.detach(), dim=-1)
    return RaySamples(bins)


class ProposalSchedule:
    """When the proposal nets get gradients and how their weights are annealed (nerfstudio's schedule).

    Stateless in ``step`` so that a resumed run makes the same choices as an
    uninterrupted one.
    """

    def __init__(self, config: SamplingConfig) -> None:
        self.config = config

    def anneal(self, step: int) -> float:
        """Exponent applied to proposal weights before PDF sampling: 0 -> 1 over anneal_max_steps."""
        frac = float(np.clip(step / max(self.config.anneal_max_steps, 1), 0.0, 1.0))
        b = self.config.anneal_slope
        return (b * frac) / ((b - 1.0) * frac + 1.0)

    def update_interval(self, step: int) -> int:
        c = self.config
        return int(np.clip(np.interp(step, [0, max(c.update_warmup, 1)], [0, c.update_every]), 1, c.update_every))

    def updates_proposals(self, step: int) -> bool:
        """True on steps where the proposal densities are computed with gradients."""
        return step < 10 or step % self.update_interval(step) == 0
