"""Fixtures of the export tests: a tiny capture with its truth dataset, a truth-backed run, a real tiny run.

Geometry tests use ``TruthRun`` (export_truth_run.py: the capture's ray caster behind the render API),
so they check the export (fusion, object parts, cropping, formats), not how far a few training steps
got. The CLI tests use a real LiveScene run trained for a few steps (``tiny_trained_run``).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from export_truth_run import TruthRun
from tiny_capture_spec import small_spec

from stages.capture import SceneRenderer, capture_to_dataset, generate_capture
from stages.model import Trainer, load_config
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES
from stages.scene import SceneDataset, read_scene


@pytest.fixture(scope="session")
def tiny_capture_dataset(tmp_path_factory) -> tuple[Path, SceneDataset, SceneRenderer]:
    """(capture folder, its truth dataset with every frame a training frame, the truth renderer)."""
    work = tmp_path_factory.mktemp("export_capture")
    spec = small_spec(n_frames=12)
    capture = generate_capture(spec, work / "capture", progress=False)
    ds = capture_to_dataset(capture, work / "dataset", split="alternate", progress=False)
    return capture, read_scene(ds.root), SceneRenderer(spec)


@pytest.fixture
def truth_run(tiny_capture_dataset) -> TruthRun:
    return TruthRun(tiny_capture_dataset[2])


@pytest.fixture(scope="session")
def tiny_trained_run(tiny_capture_dataset, tmp_path_factory) -> Path:
    """A real LiveScene run on the tiny capture, a few steps (plumbing, not quality)."""
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("export_run") / "run"
    overrides = [*TINY_MODEL_OVERRIDES, "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=100",
                 "train.eval_rays=64", "train.checkpoint_every=100", "train.render_chunk=1024", "train.threads=1",
                 "train.max_steps=4"]
    config = load_config("cpu-demo", overrides, data=str(tiny_capture_dataset[1].root), seed=0)
    Trainer(config, out, device="cpu", progress=False).train()
    return out
