"""The small ReLU MLPs every field decodes its features with (plain torch, no tiny-cuda-nn)."""

from __future__ import annotations

from torch import nn


def mlp(in_dim: int, hidden: int, n_hidden: int, out_dim: int) -> nn.Sequential:
    """Plain ReLU MLP with ``n_hidden`` hidden layers of width ``hidden`` (0 = linear)."""
    layers: list[nn.Module] = []
    d = in_dim
    for _ in range(n_hidden):
        layers += [nn.Linear(d, hidden), nn.ReLU(inplace=True)]
        d = hidden
    layers.append(nn.Linear(d, out_dim))
    return nn.Sequential(*layers)
