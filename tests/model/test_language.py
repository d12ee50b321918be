"""The language table and the language targets: linear interpolation between state levels, by hand."""

from __future__ import annotations

import math

import numpy as np
import torch

from stages.model.fields import LanguageTable
from stages.model.language_targets import LanguageTargets

E = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]  # three unit entries of one object, at buckets 0, 0.5 and 1


def _unit(v: list[float]) -> torch.Tensor:
    n = math.sqrt(sum(x * x for x in v))
    return torch.tensor([x / n for x in v])


def test_table_entries_are_interpolated_between_neighbouring_buckets():
    table = LanguageTable(1, 3, 2, init=torch.tensor([E]), background=torch.tensor([0.0, -1.0]))
    # buckets at 0, 0.5, 1: 0.25 is halfway from bucket 0 to 1, 0.6 is a fifth of the way from bucket 1 to 2
    got = table(torch.tensor([0, 0]), torch.tensor([0.25, 0.6]))
    torch.testing.assert_close(got[0], _unit([0.5, 0.5]))
    torch.testing.assert_close(got[1], _unit([-0.2, 0.8]))
    # the rendered form (summed region weights): all of ray 0 on the object at 0.25; ray 1 half object, half background
    rendered = table.render(torch.tensor([[1.0, 0.0], [0.5, 0.5]]), torch.tensor([[0.25, 0.0], [0.6, 0.0]]))
    torch.testing.assert_close(rendered[0], _unit([0.5, 0.5]))
    torch.testing.assert_close(rendered[1], 0.5 * _unit([-0.2, 0.8]) + 0.5 * torch.tensor([0.0, -1.0]))


def test_render_language_does_not_train_the_rendering_weights():
    """The docstring: the weights are detached, as the language loss trains the table only."""
    from stages.model.config import ModelConfig
    from stages.model.methods import LiveSceneModel, SceneInfo

    cfg = ModelConfig()
    cfg.field.base_resolution, cfg.field.channels, cfg.field.scales = 8, 4, [1]
    cfg.proposal.resolutions, cfg.sampling.num_proposal_samples = [[8, 4]], [8]
    cfg.probability.resolution = 8
    model = LiveSceneModel(cfg, SceneInfo(objects=["o0"], n_frames=4, language_dim=2, language_levels=3))
    weights = torch.tensor([[0.2, 0.5, 0.3], [0.6, 0.1, 0.1]], requires_grad=True)
    logits = torch.tensor([[[3.0, 0.0], [3.0, 0.0], [0.0, 3.0]], [[0.0, 3.0], [3.0, 0.0], [3.0, 0.0]]])
    out = model.render_language(weights, logits, torch.tensor([[0.3], [0.8]]), torch.zeros(2))
    out.sum().backward()
    assert weights.grad is None
    assert model.language_table.table.grad is not None and model.language_table.table.grad.abs().sum() > 0


def test_language_targets_interpolate_linearly_at_the_objects_state():
    # two levels 0 and 1: state 0.25 gives 0.75 e0 + 0.25 e1, normalised
    two = LanguageTargets(np.array([0.0, 1.0]), np.array([E[:2]]), np.array([-1.0, 0.0]), "t")
    got = two.targets(torch.tensor([0]), torch.tensor([[0.25]]))
    torch.testing.assert_close(got[0], _unit([0.75, 0.25]))  # (0.9487, 0.3162)
    # three levels 0, 0.5, 1: state 0.6 is a fifth of the way from level 0.5 to level 1
    three = LanguageTargets(np.array([0.0, 0.5, 1.0]), np.array([E]), np.array([-1.0, 0.0]), "t")
    torch.testing.assert_close(three.targets(torch.tensor([0]), torch.tensor([[0.6]]))[0], _unit([-0.2, 0.8]))
    # label alpha = 1 is the background: its embedding, whatever the state; -1 (no label) does not fail
    labels = torch.tensor([1, -1])
    got = three.targets(labels, torch.tensor([[0.6], [0.6]]))
    torch.testing.assert_close(got[0], torch.tensor([-1.0, 0.0]))
    assert got.shape == (2, 2) and torch.isfinite(got).all()
