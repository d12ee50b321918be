"""Fixtures of the model tests: a tiny training config and a trained tiny run (a few steps)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from stages.model import Trainer, load_config
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES

TINY = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=2", "train.eval_rays=64",
    "train.checkpoint_every=100", "train.render_chunk=256", "train.threads=1", "train.max_seconds=0",
]


@pytest.fixture(autouse=True)
def _few_threads():
    torch.set_num_threads(1)


def _tiny_config(data: Path, *extra: str, steps: int = 4, seed: int = 0):
    return load_config("cpu-demo", [*TINY, f"train.max_steps={steps}", *extra], data=str(data), seed=seed)


@pytest.fixture
def tiny_config():
    """``tiny_config(data, *overrides, steps=4)``: a RunConfig small enough to train in well under a second."""
    return _tiny_config


@pytest.fixture
def tiny_overrides() -> list[str]:
    return list(TINY)


@pytest.fixture
def trained_run(tiny_dataset, tmp_path) -> Path:
    out = tmp_path / "run"
    Trainer(_tiny_config(tiny_dataset.root), out, device="cpu", progress=False).train()
    return out
