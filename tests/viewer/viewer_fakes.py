"""Test doubles of the viewer tests: a tiny run whose object states show in the image."""

from __future__ import annotations

from pathlib import Path

import torch
from tiny_language_run import train_tiny_language_run

from stages.model import load_run
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES

TINY_RUN = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=100", "train.eval_rays=64",
    "train.checkpoint_every=100", "train.render_chunk=1024", "train.threads=1", "train.max_steps=30",
    # every sample follows the state of its most probable object (the preset rejects weak ones: after 4 steps all)
    "model.probability.rejection_threshold=0",
    # after 30 steps the rays are still mostly transparent: what a state changes shows against a fixed background,
    # not behind the preset's last sample (whose colour the state barely moves)
    "model.sampling.background_mode=fixed",
]


def make_states_visible(run_dir: Path, seed: int = 0) -> None:
    """Scale the run's state planes by fixed random factors, so that every object's state changes the image.

    A few training steps cannot teach the planes over the state axis anything (they start at 1, docs/model.md),
    and with them at 1 a slider would change nothing the viewer tests could see. The factors are in [0.1, 2.5].
    """
    path = run_dir / "model.pt"
    payload = torch.load(path, map_location="cpu", weights_only=True)
    run = load_run(run_dir)
    gen = torch.Generator().manual_seed(seed)
    touched = 0
    with torch.no_grad():
        for module in run.model.modules():
            for i in getattr(module, "k_plane_indices", []):
                plane = module.planes[i]
                plane.mul_(torch.empty(plane.shape).uniform_(0.1, 2.5, generator=gen))
                touched += 1
    assert touched, "no K-Planes state planes found: the model stage changed, update make_states_visible"
    payload["state_dict"] = run.model.state_dict()
    torch.save(payload, path)


def make_viewer_run(work: Path) -> tuple[Path, Path]:
    """(dataset, run): the shared tiny language run (tests/tiny_language_run.py), 30 steps, its state planes
    made visible."""
    _, dataset, run = train_tiny_language_run(work, TINY_RUN)
    make_states_visible(run)
    return dataset, run
