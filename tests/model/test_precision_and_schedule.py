"""Mixed precision on the CPU, the learning-rate schedule with a time budget, learned-state evaluation."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
import torch

from stages.model import Trainer
from stages.model.trainer import autocast_dtype, lr_factor


@pytest.mark.parametrize("precision", ["bf16", "fp16"])
def test_cpu_autocast_trains_with_finite_losses(tiny_dataset, tmp_path, tiny_config, precision):
    cfg = tiny_config(tiny_dataset.root, f"train.mixed_precision={precision}", steps=3)
    trainer = Trainer(cfg, tmp_path / precision, device="cpu", progress=False)
    assert trainer.amp_dtype == {"bf16": torch.bfloat16, "fp16": torch.float16}[precision]
    assert (trainer.scaler is not None) == (precision == "fp16")
    seen: list[torch.dtype] = []  # the field's first linear layer really runs in the reduced dtype
    first = next(m for m in trainer.model.field.density_mlp.modules() if isinstance(m, torch.nn.Linear))
    first.register_forward_hook(lambda m, i, o: seen.append(o.dtype))
    trainer.train()
    assert seen and set(seen) == {trainer.amp_dtype}
    with (tmp_path / precision / "train_log.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3  # no step was skipped as non-finite
    assert all(math.isfinite(float(r["loss"])) for r in rows)
    assert all(bool(torch.isfinite(p).all()) for p in trainer.model.parameters())


def test_autocast_setting():
    cpu = torch.device("cpu")
    assert autocast_dtype("auto", cpu) is None and autocast_dtype("off", cpu) is None
    assert autocast_dtype("bf16", cpu) == torch.bfloat16 and autocast_dtype("fp16", cpu) == torch.float16
    with pytest.raises(Exception, match="mixed_precision"):
        autocast_dtype("fp8", cpu)


def test_lr_warmup_cosine_and_time_budget():
    assert lr_factor(0, 10, 100, 0.0) == pytest.approx(0.1)
    assert lr_factor(9, 10, 100, 0.0) == pytest.approx(1.0)
    assert lr_factor(10, 10, 100, 0.0) == pytest.approx(1.0)
    assert lr_factor(55, 10, 100, 0.0) == pytest.approx(0.5)
    assert lr_factor(100, 10, 100, 0.1) == pytest.approx(0.1)
    # half the wall-clock budget spent early in the step budget: the decay is half way
    assert lr_factor(20, 10, 1000, 0.0, time_fraction=0.5) == pytest.approx(0.5)
    assert lr_factor(20, 10, 1000, 0.0, time_fraction=1.0) == pytest.approx(0.0, abs=1e-12)
    assert lr_factor(5, 10, 1000, 0.0, time_fraction=0.1) == pytest.approx(0.6)  # warm-up is by step
    # a budget shorter than the warm-up: the run still ends at a low rate, not at the warm-up's
    assert lr_factor(5, 10, 1000, 0.0, time_fraction=0.9) == pytest.approx(0.5 * (1 + math.cos(0.9 * math.pi)))
    assert lr_factor(5, 10, 1000, 0.0, time_fraction=1.0) == pytest.approx(0.0, abs=1e-12)


def test_learned_state_rays_carry_no_states_and_eval_uses_the_state_field(tiny_dataset, tmp_path, tiny_config):
    cfg = tiny_config(tiny_dataset.root, "model.state.mode=learned", steps=1)
    trainer = Trainer(cfg, tmp_path / "learned", device="cpu", progress=False)
    batch = trainer.eval_rays.batch(torch.arange(8))
    assert batch.rays.states is None and batch.rays.times is not None
    trainer.model.eval()
    expected = trainer.model.state_field(batch.rays.times)
    torch.testing.assert_close(trainer.model.ray_states(batch.rays), expected)
    given = Trainer(tiny_config(tiny_dataset.root, steps=1), tmp_path / "given", device="cpu", progress=False)
    rays = given.eval_rays.batch(torch.arange(8)).rays
    assert rays.states is not None and np.isfinite(rays.states.numpy()).all()


def test_rgb_gradient_reaches_learned_states_through_k(tiny_dataset, tmp_path, tiny_config):
    cfg = tiny_config(tiny_dataset.root, "model.state.mode=learned", "model.probability.rejection_threshold=0", steps=1)
    trainer = Trainer(cfg, tmp_path / "learned", device="cpu", progress=False)
    model = trainer.model
    with torch.no_grad():  # k planes start at 1 (no k dependence); give them some so d rgb / d kappa != 0
        for grid in model.field.encoding.grids:
            for i in grid.k_plane_indices:
                grid.planes[i].uniform_(0.5, 1.5)
    batch = trainer.train_rays.sample(64, torch.Generator().manual_seed(0))
    out = model(batch.rays, step=100)
    torch.nn.functional.mse_loss(out["rgb"], batch.rgb).backward()
    grads = [p.grad for p in model.state_field.parameters()]
    assert all(g is not None for g in grads) and any(float(g.abs().sum()) > 0 for g in grads)
    spatial = model.field.encoding.grids[0].plane_groups[0]  # spatial planes (xy, xz, yz) still learn from rgb
    assert spatial.grad is not None and float(spatial.grad.abs().sum()) > 0


def test_frame_time_spans_zero_to_one_over_evenly_numbered_frames():
    from stages.model.methods import SceneInfo

    info = SceneInfo(objects=[], n_frames=5)
    assert [info.frame_time(i) for i in range(5)] == [0.0, 0.25, 0.5, 0.75, 1.0]  # i / (n - 1)
    assert SceneInfo(objects=[], n_frames=1).frame_time(0) == 0.0


def test_key_frames_every_n_frames_sit_at_their_frames_times(tiny_dataset, tiny_config):
    # six frames numbered 0..5: times i / 5. Every second frame is a key frame: 0, 2, 4 -> 0, 0.4, 0.8, each frame's
    # own state; rendering (SceneInfo.frame_time) and training (frame_times) agree on every frame
    from stages.model.trainer import scene_info
    from stages.scene.key_frame_states import frame_times

    cfg = tiny_config(tiny_dataset.root, "model.state.key_frame_every=2")
    info = scene_info(tiny_dataset, cfg, None)
    assert info.key_times == pytest.approx([0.0, 0.4, 0.8], abs=1e-7)
    objects = tiny_dataset.objects
    expect = [tiny_dataset.frames[i].state[o] for i in (0, 2, 4) for o in objects]
    assert [v for row in info.key_states for v in row] == pytest.approx(expect, abs=1e-6)  # stored as float32
    times = frame_times(tiny_dataset.frames)
    assert [info.frame_time(i) for i in range(6)] == pytest.approx([i / 5 for i in range(6)], abs=1e-7)
    assert [info.frame_time(i) for i in range(6)] == pytest.approx(list(times), abs=1e-7)
