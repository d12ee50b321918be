"""Train a tiny LiveScene for a few steps and collect what the stability checks check.

The config is the ``cpu-demo`` preset shrunk to a few hundred parameters per
plane, so a step takes milliseconds; the trainer, its non-finite guards and the
model code are exactly those of ``livescene train``. The checks here are plain
``assert`` statements that conftest.py registers for pytest's assertion
rewriting, so they hold under ``python -O`` as they do in the test modules.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from stages.model import Trainer, load_config
from stages.model.tiny_overrides import TINY_MODEL_OVERRIDES

TINY_MODEL = [
    *TINY_MODEL_OVERRIDES,
    "train.batch_rays=64", "train.warmup_steps=2", "train.eval_every=0", "train.eval_rays=256",
    "train.checkpoint_every=0", "train.render_chunk=512", "train.threads=0",
    # no wall-clock budget: with one, the LR decay follows elapsed time and no two runs are bit-identical
    "train.max_seconds=0",
]
"""Overrides of the cpu-demo preset that make a step take milliseconds on one core, reproducibly."""


@dataclass
class BriefRun:
    """What a few training steps produced."""

    trainer: Any
    """The stages.model Trainer (model, rays, optimiser) after the steps."""
    losses: list[float] = field(default_factory=list)
    """Total loss of every step that was taken (skipped steps have none)."""
    skipped: int = 0
    """Steps the trainer skipped for a non-finite loss or gradient."""
    first_terms: dict[str, float] = field(default_factory=dict)
    last_terms: dict[str, float] = field(default_factory=dict)

    @property
    def first(self) -> float:
        return self.losses[0] if self.losses else math.nan

    @property
    def last(self) -> float:
        return self.losses[-1] if self.losses else math.nan

    def summary(self) -> str:
        return f"loss {self.first:.4g} -> {self.last:.4g} in {len(self.losses)} steps, {self.skipped} skipped"


def nonfinite_grads(model: torch.nn.Module) -> list[str]:
    """Names of the parameters whose gradient holds a NaN or inf."""
    return [n for n, p in model.named_parameters() if p.grad is not None and not bool(torch.isfinite(p.grad).all())]


def make_trainer(data: Path, out: Path, *, steps: int, overrides: list[str] | None = None, seed: int = 0,
                 device: str = "cpu") -> Any:
    config = load_config("cpu-demo", [*TINY_MODEL, f"train.max_steps={steps}", *(overrides or [])],
                         data=str(data), seed=seed)
    return Trainer(config, out, device=device, progress=False)


def train_briefly(data: Path, out: Path, *, steps: int, overrides: list[str] | None = None, seed: int = 0,
                  device: str = "cpu") -> BriefRun:
    """``steps`` optimisation steps; every taken step's loss and gradients are checked finite."""
    trainer = make_trainer(data, out, steps=steps, overrides=overrides, seed=seed, device=device)
    run = BriefRun(trainer)
    for _ in range(steps):
        trainer.train_step()
        result = trainer.flush_steps()[-1]
        trainer.step += 1
        if result is None:
            run.skipped += 1
            continue
        assert all(math.isfinite(v) for v in result.values()), f"step {trainer.step}: non-finite loss {result}"
        bad = nonfinite_grads(trainer.model)
        assert not bad, f"step {trainer.step}: non-finite gradients in {bad[:3]}"
        if not run.losses:
            run.first_terms = dict(result)
        run.last_terms = dict(result)
        run.losses.append(float(result["loss"]))
    bad = [n for n, p in trainer.model.named_parameters() if not bool(torch.isfinite(p).all())]
    assert not bad, f"parameters not finite after training: {bad[:3]}"
    return run


def require_learning(run: BriefRun, what: str) -> None:
    """The 'useful result' half of a check: no skipped step, and the loss went down."""
    assert run.skipped == 0, (
        f"{what}: {run.skipped} of {run.skipped + len(run.losses)} steps were skipped as "
        "non-finite")
    assert run.last < run.first, f"{what}: loss did not decrease ({run.summary()})"


@torch.no_grad()
def render_held_out(run: BriefRun, n_rays: int = 256) -> dict[str, float]:
    """Render held-out rays in eval mode; every output must be finite. Returns PSNR and accumulation range."""
    trainer = run.trainer
    model = trainer.model
    model.eval()
    rays = trainer.eval_rays
    idx = torch.arange(0, rays.n_rays, max(rays.n_rays // n_rays, 1))[:n_rays]
    batch = rays.batch(idx)
    out = model(batch.rays, step=trainer.step)
    model.train()
    for key in ("rgb", "depth", "accumulation", "logits"):
        assert bool(torch.isfinite(out[key]).all()), f"rendered {key} has non-finite values"
    mse = float((out["rgb"].clamp(0, 1) - batch.rgb).square().mean())
    acc = out["accumulation"]
    return {"psnr": -10 * math.log10(max(mse, 1e-12)), "acc_min": float(acc.min()), "acc_max": float(acc.max())}
