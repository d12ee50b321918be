"""Volume rendering: weights sum to 1 - transmittance, stay finite for extreme densities."""

from __future__ import annotations

import torch

from stages.model.renderers import render_depth, render_rgb, render_weights


def test_weights_sum_to_one_minus_transmittance():
    g = torch.Generator().manual_seed(0)
    sigma = torch.rand(50, 32, generator=g) * 5
    deltas = torch.rand(50, 32, generator=g) * 0.1
    w = render_weights(sigma, deltas)
    transmittance = torch.exp(-(sigma * deltas).sum(-1))
    assert torch.all(w >= 0)
    assert torch.allclose(w.sum(-1), 1 - transmittance, atol=1e-6)
    # the classic alpha-compositing form gives the same weights
    alpha = 1 - torch.exp(-sigma * deltas)
    trans = torch.cumprod(torch.cat([torch.ones(50, 1), 1 - alpha[:, :-1]], -1), -1)
    assert torch.allclose(w, alpha * trans, atol=1e-6)


def test_extreme_densities_give_finite_weights_and_colours():
    sigma = torch.tensor([[0.0, 0.0, 0.0], [1e30, 1e30, 1e30], [float("inf"), 1.0, 1.0],
                          [float("nan"), 1e38, 0.0], [1e-30, 1e-30, 1e-30]])
    deltas = torch.tensor([0.1, 0.0, 0.1]).expand(5, 3)
    w = render_weights(sigma, deltas)
    assert torch.isfinite(w).all() and torch.all(w >= 0) and torch.all(w.sum(-1) <= 1 + 1e-6)
    assert w[0].sum() == 0  # empty space: nothing visible
    assert w[1, 0].item() == 1.0  # an opaque first sample takes all the weight
    assert w[2, 0].item() == 1.0
    rgb = render_rgb(w, torch.rand(5, 3, 3), torch.tensor([1.0, 1.0, 1.0]))
    assert torch.isfinite(rgb).all()
    assert torch.allclose(rgb[0], torch.ones(3))  # empty ray shows the background
    depth = render_depth(w, torch.tensor([1.0, 2.0, 3.0]).expand(5, 3), torch.full((5,), 0.5), torch.full((5,), 4.0))
    assert torch.isfinite(depth).all() and torch.all(depth >= 0.5) and torch.all(depth <= 4.0)


def test_gradients_finite_at_extreme_densities():
    raw = torch.tensor([[0.0, 50.0, -50.0, 30.0]], requires_grad=True)
    from stages.model.fields.activations import trunc_exp

    w = render_weights(trunc_exp(raw), torch.full((1, 4), 0.05))
    w.sum().backward()
    assert torch.isfinite(raw.grad).all()
