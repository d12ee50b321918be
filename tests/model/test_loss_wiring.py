"""Every loss term of ``LiveSceneModel.loss_dict`` is scaled by its own weight in ``LossWeights``."""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from stages.model import build_model, load_config
from stages.model.config import LossWeights
from stages.model.language_targets import LanguageTargets
from stages.model.methods import SceneInfo
from stages.model.ray_dataset import RayBatch
from stages.model.rays import RayBundle

WEIGHTS = [f.name for f in dataclasses.fields(LossWeights) if f.type in ("float", float)
           and f.name != "repulsion_margin"]


def test_each_weight_turns_on_its_own_term_only(tiny_overrides):
    # every term can exist: learned states with key frames, a language table and targets, per-frame corrections
    cfg = load_config("cpu-demo", [*tiny_overrides, "model.state.mode=learned", "model.appearance.mode=affine"])
    info = SceneInfo(objects=["o0", "o1"], n_frames=4, key_times=[0.0, 1.0], key_states=[[0.2, 0.4], [0.8, 0.6]],
                     language_dim=3, language_levels=2)
    torch.manual_seed(0)
    model = build_model("livescene", cfg.model, info).train()
    assert model.proposal_fields and model.state_field is not None and model.language_table is not None
    n = 16
    g = torch.Generator().manual_seed(0)
    d = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1)
    rays = RayBundle(torch.zeros(n, 3), d, torch.full((n,), 0.05), torch.full((n,), 1.5), None,
                     torch.rand(n, generator=g))
    out = model(rays, step=300, generator=g)
    labels = torch.tensor([0, 1, 2, -1] * 4)
    batch = RayBatch(rays, torch.rand(n, 3, generator=g), labels, torch.arange(n) % 4)
    targets = LanguageTargets(np.array([0.0, 1.0]), np.random.default_rng(0).normal(size=(2, 2, 3)),
                              np.array([1.0, 0.0, 0.0]), "test")
    assert {"rgb", "language", "state_mse", "appearance", "k_smoothness_proposal"} <= set(WEIGHTS)
    for name in WEIGHTS:
        for other in WEIGHTS:
            setattr(model.config.losses, other, 1.0 if other == name else 0.0)
        terms = model.loss_dict(out, batch, 300, targets)
        assert set(terms) == {name}, name
        assert torch.isfinite(terms[name]), name

