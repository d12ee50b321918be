"""The interaction probability field (docs/method.md section 2): which object's state drives each point.

A tri-plane (xy, xz, yz; planes multiplied; sigmoid) is sampled at the
normalised position and decoded together with the whole state vector by an
MLP into ``alpha + 1`` logits (background last). The argmax over the object
logits picks the object ``u`` whose state ``kappa_u`` becomes the sample's 4th
coordinate: 3 + alpha dimensions are projected to 4. The argmax has no
gradient, so the logits are trained by the mask losses only.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..config import ProbabilityConfig
from ..encodings import KPlanesEncoding, PlaneGrids
from ..mlp import mlp


class ProbabilityField(nn.Module):
    """Positions [N, 3] in [-1, 1] and states [N, alpha] -> logits [N, alpha + 1]."""

    def __init__(self, config: ProbabilityConfig, n_objects: int, k_resolution: int | None = None) -> None:
        super().__init__()
        self.config = config
        self.n_objects = n_objects
        # ``static_row``: where objects' states start on the k axis (the first vertex is the static room's); the
        # k resolution is the radiance field's, which the model passes
        self.state_floor = 1.0 / (k_resolution - 1) if config.static_row and k_resolution and k_resolution > 1 else 0.0
        r = config.resolution
        self.encoding = KPlanesEncoding([r, r, r], config.channels, None, 3, config.init_range)
        # with state_input "none" the states are not an input: n_inputs = 0
        self.n_inputs = n_objects if config.state_input == "all" else 0
        self.decoder = mlp(config.channels + self.n_inputs, config.hidden, 1, n_objects + 1)

    def forward(self, positions: torch.Tensor, states: torch.Tensor, cache: PlaneGrids | None = None) -> torch.Tensor:
        """``positions`` [N, 3] and ``states`` [N, alpha], or [R, alpha] per ray with N = R x samples -> [N, alpha + 1].

        The decoder's first layer is applied to the features and the states
        separately (the same sum as on their concatenation), so a state vector
        per ray is never copied out to every sample.
        """
        features = torch.sigmoid(self.encoding(positions, cache))
        first, rest = self.decoder[0], self.decoder[1:]
        c = features.shape[-1]
        n, r = features.shape[0], states.shape[0]
        # one state vector for every ray (a rendered view): its term is a constant, folded into the bias
        shared = self.n_inputs > 0 and r < n and states.stride(0) == 0
        bias = first.bias + F.linear(states[0].to(features.dtype), first.weight[:, c:]) if shared else first.bias
        h = F.linear(features, first.weight[:, :c], bias)
        if self.n_inputs > 0 and not shared:
            hs = F.linear(states.to(h.dtype), first.weight[:, c:])
            # in place: a broadcast add into a new [N, hidden] array costs as much as the layer itself
            (h if r == n else h.view(r, n // r, -1)).add_(hs if r == n else hs[:, None, :])
        return rest(h).float()

    def project(self, logits: torch.Tensor, states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The k coordinate of every sample: ``kappa_u`` with ``u`` = argmax over the object logits.

        ``logits`` [N, alpha + 1], ``states`` [N, alpha] -> (k [N] in [0, 1], u [N] long).
        Samples whose best object probability is under the rejection threshold
        get the static value; with ``static_row`` the objects' states are moved off the static value's vertex.
        ``k`` keeps the gradient of ``states`` (learned-state mode).
        """
        if self.n_objects == 0:  # a static scene: every sample sits at the static value
            z = torch.zeros(logits.shape[0], dtype=torch.long, device=logits.device)
            return torch.full_like(logits[:, 0], self.config.static_value), z
        with torch.no_grad():
            # classes as rows: reductions over alpha + 1 values per sample are row ops, not a short inner loop
            # per sample (a softmax over [N, 3] costs 2.5x this on the CPU)
            rows = logits.detach().float().t().contiguous()
            best, u = rows[: self.n_objects].max(dim=0)
            if self.config.rejection_threshold > 0:
                # softmax_u >= t  <=>  sum_j exp(l_j - l_u) <= 1 / t; overflow gives inf, i.e. "unsure"
                sure = torch.exp(rows - best).sum(dim=0) <= 1.0 / self.config.rejection_threshold
        k = torch.gather(states, 1, u[:, None])[:, 0]
        if self.state_floor > 0:
            k = self.state_floor + (1.0 - self.state_floor) * k
        if self.config.rejection_threshold > 0:
            k = torch.where(sure, k, torch.full_like(k, self.config.static_value))
        return k, u
