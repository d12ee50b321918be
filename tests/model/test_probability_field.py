"""The argmax k-projection: each sample takes the state of the object whose logit wins."""

from __future__ import annotations

import torch

from stages.model.config import ProbabilityConfig
from stages.model.fields import ProbabilityField


def test_projection_picks_kappa_of_the_argmax_object_ignoring_background():
    field = ProbabilityField(ProbabilityConfig(), n_objects=3)
    states = torch.tensor([[0.1, 0.5, 0.9]]).expand(4, 3)
    logits = torch.tensor([
        [5.0, 0.0, 0.0, 0.0],   # object 0
        [0.0, 0.0, 3.0, 0.0],   # object 2
        [0.0, 2.0, 1.0, 9.0],   # background largest: argmax over objects only -> object 1
        [-1.0, -2.0, -0.5, -3.0],  # object 2
    ])
    k, u = field.project(logits, states)
    assert u.tolist() == [0, 2, 1, 2]
    assert torch.allclose(k, torch.tensor([0.1, 0.9, 0.5, 0.9]))


def test_projection_keeps_state_gradient_and_rejects_unsure_samples():
    field = ProbabilityField(ProbabilityConfig(rejection_threshold=0.6, static_value=0.0), n_objects=2)
    states = torch.tensor([[0.3, 0.8], [0.3, 0.8]], requires_grad=True)
    logits = torch.tensor([[10.0, 0.0, 0.0], [0.0, 0.1, 0.0]])  # sure about object 0; unsure about object 1
    k, u = field.project(logits, states)
    assert u.tolist() == [0, 1]
    assert torch.allclose(k, torch.tensor([0.3, 0.0]))
    k.sum().backward()
    assert states.grad[0].tolist() == [1.0, 0.0]


def test_field_learns_regions_from_position():
    """The full field (tri-plane + decoder) fed positions returns alpha + 1 logits per sample."""
    torch.manual_seed(0)
    field = ProbabilityField(ProbabilityConfig(resolution=8, channels=4, hidden=8), n_objects=2)
    pos = torch.rand(32, 3) * 2 - 1
    logits = field(pos, torch.rand(32, 2))
    assert logits.shape == (32, 3) and torch.isfinite(logits).all()
